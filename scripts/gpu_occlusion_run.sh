#!/usr/bin/env bash
# scripts/gpu_occlusion_run.sh: issue 72's occlusion-culling rows on the GPU machine, in one call.
# exact and exact-occlusion (RenderOptions::occlusion_culling: list entries behind the last
# frame's opaque pixels are dropped; render_core/forward_model/occlusion.h) side by side in one
# catgs-bench process per city x real camera path, at the server's picture: 1280x720, the LOD at
# 2 px, 10 warm-up + 96 timed frames at 120 FPS, every 12th frame against the 4x supersampled
# full-detail render (--aa-reference 4: the issue's yardstick).
#
# On the build machine, once: scripts/gpu_run.sh prepare build/cpu   (fills .carry/; the GPU
# binaries are built on the GPU machine, so .carry/bin may be removed)
# On the GPU machine, carry [".carry"]:
#   scripts/gpu_occlusion_run.sh [--prebuilt] [STAGE...]
#     stages: tests (the gpu.Occlusion, gpu.Equality and gpu.Lod GoogleTest cases: CUDA against
#     the CPU reference), cityN:PATH (N copies: 13, 101 or 197; PATH: bicycle, train, flowers),
#     changesN:PATH (the CPU reference's measurement of the entries and Gaussians that change a
#     pixel, 4 frames: catgs-bench --renderer cpu --count-changes).
#     Default: tests city197:bicycle city13:bicycle.
#   -> $OUT/occlusion_table.md (one row per city x path x variant), $OUT/occlusion.tar.gz (the
#      JSONs), $OUT/occlusion.log, $OUT/build/gpu_tests.md.
#   A stage that would start after $CATGS_OCC_BUDGET_S seconds (default 520) is skipped with a
#   line saying so: run it in a call of its own (--prebuilt reuses the machine's build/gpu).
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
CARRY=$ROOT/.carry
OUT=${OUT:-$ROOT/out/gpu_occlusion}
BUDGET=${CATGS_OCC_BUDGET_S:-520}
mkdir -p "$OUT/json"
exec > >(tee -a "$OUT/occlusion.log") 2>&1
echo "== gpu_occlusion_run.sh $(date -u +%FT%TZ) $(nproc) cores"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader 2>/dev/null || echo "no nvidia-smi"

PREBUILT=0
[ "${1:-}" = --prebuilt ] && { PREBUILT=1; shift; }
stages=("$@")
[ "${#stages[@]}" -gt 0 ] || stages=(tests city197:bicycle city13:bicycle)
BIN=$ROOT/build/gpu/bin
if [ "$PREBUILT" = 0 ]; then
  filter=NONE
  for s in "${stages[@]}"; do [ "$s" = tests ] && filter='gpu\.(Occlusion|Equality|Lod)\.'; done
  if [ "$filter" = NONE ]; then
    OUT=$OUT/build scripts/gpu_run.sh --no-tests --no-bench || { echo "build failed"; exit 1; }
  else
    OUT=$OUT/build scripts/gpu_run.sh --no-bench --filter "$filter" || echo "== some GPU tests FAILED"
  fi
fi
S=$CARRY/scenes T=$CARRY/traces
status=0

city() {  # city COPIES PATH
  local r
  case "$1" in 13) r=4 ;; 101) r=32 ;; 197) r=64 ;; *) echo "no city of $1 copies"; return 1 ;; esac
  local trace
  case "$2" in bicycle) trace=mipnerf360_bicycle ;; train) trace=tandt_train ;; flowers) trace=flowers_sh3 ;;
    *) echo "no path $2"; return 1 ;; esac
  "$BIN/catgs-bench" --scene "$S/tumblewood_sh2.compressed.ply" --city --radius-sq "$r" --up 0,-1,0 \
    --lod --lod-error 2 --trace "real:$T/$trace.cameras.json" --width 1280 --height 720 \
    --pipeline exact,exact-occlusion --warmup 10 --frames 96 --quality-every 12 --aa-reference 4 \
    --json "$OUT/json/occ_city$1_$2${CATGS_OCC_TAG:-}.json"
}

# changes COPIES PATH: where the list's work goes, measured by the CPU reference on the machine's
# cores (catgs-bench --renderer cpu --count-changes: entries and Gaussians that change a pixel,
# entries behind their tile's opaque point, and what the frame's own per-pixel map could drop at
# best: whole chunks of the cut, whole Gaussians, entries), 2 + 4 frames, exact and exact-occlusion.
changes() {
  local r trace
  case "$1" in 13) r=4 ;; 101) r=32 ;; 197) r=64 ;; *) echo "no city of $1 copies"; return 1 ;; esac
  case "$2" in bicycle) trace=mipnerf360_bicycle ;; train) trace=tandt_train ;; flowers) trace=flowers_sh3 ;;
    *) echo "no path $2"; return 1 ;; esac
  "$BIN/catgs-bench" --renderer cpu --scene "$S/tumblewood_sh2.compressed.ply" --city --radius-sq "$r" \
    --up 0,-1,0 --lod --lod-error 2 --trace "real:$T/$trace.cameras.json" --width 1280 --height 720 \
    --pipeline exact,exact-occlusion --warmup 2 --frames 4 --quality-every 0 --count-changes \
    --json "$OUT/json/changes_city$1_$2.json"
}

for s in "${stages[@]}"; do
  [ "$s" = tests ] && continue
  if [ "$SECONDS" -ge "$BUDGET" ]; then
    echo "== stage $s SKIPPED: $SECONDS s into the call (budget $BUDGET s); run it in a call of its own"
    status=1
    continue
  fi
  t0=$SECONDS
  case "$s" in
    city*) n=${s#city}; city "${n%%:*}" "${s#*:}" ;;
    changes*) n=${s#changes}; changes "${n%%:*}" "${s#*:}" ;;
    *) echo "unknown stage $s"; false ;;
  esac || { echo "stage $s FAILED"; status=1; }
  echo "== stage $s: $((SECONDS - t0)) s"
done

python3 - "$OUT/json" > "$OUT/occlusion_table.md" <<'PY' || status=1
import glob, json, os, sys
print("| city x path | variant | ms a frame mean / p99 | pre / keys / sort / ranges / raster ms | chunks pre-processed | "
      "list entries | visible Gaussians | PSNR vs 4x supersampled mean / min dB |")
print("|---|---|---|---|---|---|---|---|")
changes = sorted(glob.glob(os.path.join(sys.argv[1], "changes_city*.json")))
for path in sorted(glob.glob(os.path.join(sys.argv[1], "occ_city*.json"))):
    j = json.load(open(path))
    for p in j.get("pipelines", []):
        st = p["stages_ms_mean"]
        a = p.get("quality_vs_aa_reference") or {}
        chunks = p.get("chunks_preprocessed_mean")
        print("| %s | %s | %.3f / %.3f | %.2f / %.2f / %.2f / %.2f / %.2f | %s | %.2f M | %.2f M | %s |" % (
            os.path.basename(path)[4:-5], p["pipeline"], p["frame_ms"]["mean"], p["frame_ms"]["p99"],
            st["preprocess"], st["keys"], st["sort"], st["tile_ranges"], st["rasterize"],
            "%.1f k" % (chunks / 1e3) if chunks is not None else "-",
            p["render_list"]["mean"] / 1e6, p.get("visible_mean", 0) / 1e6,
            ("%.2f / %.2f" % (a["psnr_db_mean_finite"], a["psnr_db_min"])) if a else "-"))
if changes:
    print()
    print("| city x path (CPU, 4 frames) | variant | list entries | entries changing a pixel | behind the tile's opaque point | "
          "visible Gaussians | Gaussians changing a pixel | own per-pixel map: entries hidden | Gaussians hidden alone | "
          "cut's Gaussians in view / in chunks hidden whole / in runs of 32 hidden whole |")
    print("|---|---|---|---|---|---|---|---|---|---|")
for path in changes:
    j = json.load(open(path))
    for p in j.get("pipelines", []):
        L, V = p["render_list"]["mean"], p.get("visible_mean", 0)
        ce, cg, b = p["entries_changing_pixels_mean"], p["gaussians_changing_pixels_mean"], p["entries_behind_opaque_mean"]
        eh, ga = p.get("entries_hidden_pixels_mean", 0), p.get("gaussians_hidden_alone_mean", 0)
        gp, gc = p.get("gaussians_preprocessed_mean", 0), p.get("gaussians_in_hidden_chunks_mean", 0)
        gg = p.get("gaussians_in_hidden_groups_mean", 0)
        print("| %s | %s | %.2f M | %.2f M (%.1f%%) | %.2f M (%.1f%%) | %.2f M | %.2f M (%.1f%%) | %.2f M (%.1f%%) | "
              "%.2f M (%.1f%%) | %.2f M / %.2f M (%.1f%%) / %.2f M (%.1f%%) |" % (
            os.path.basename(path)[8:-5], p["pipeline"], L / 1e6, ce / 1e6, 100 * ce / max(L, 1), b / 1e6,
            100 * b / max(L, 1), V / 1e6, cg / 1e6, 100 * cg / max(V, 1), eh / 1e6, 100 * eh / max(L, 1),
            ga / 1e6, 100 * ga / max(V, 1), gp / 1e6, gc / 1e6, 100 * gc / max(gp, 1), gg / 1e6,
            100 * gg / max(gp, 1)))
PY
cat "$OUT/occlusion_table.md"
(cd "$OUT" && tar czf occlusion.tar.gz json && rm -rf json)
echo "== done: status $status in $SECONDS s"
exit $status
