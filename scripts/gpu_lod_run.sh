#!/usr/bin/env bash
# scripts/gpu_lod_run.sh: issue 37's level-of-detail table on the GPU machine, in one call: the
# 13-, 101- and 201-copy tumblewood cities (7.05 M, 54.8 M, ~109 M Gaussians), each built in
# memory by catgs-bench with its LOD (--city --lod: the build time and level sizes are printed and
# in the JSON), flown over at 1920x1080 (30 warm-up + 300 timed frames at 120 FPS) by exact and
# catgs at each bound of $CATGS_LOD_BOUNDS (default 0,1,1.5,2,2.5,4 pixels; 0 = full detail, the
# scene as it was; RenderOptions::lod_error_px is 1), every 10th frame of every variant compared
# with the full-detail exact render (PSNR), and with $CATGS_LOD_AA = F (default 0: off) also
# with the anti-aliased reference (full detail at F times the size, box-filtered: catgs-bench
# --aa-reference), the full-detail frames too; $CATGS_LOD_PIPES picks the pipelines (default
# exact,catgs); and the GPU tests' LOD rows (the gpu.Lod.* GoogleTest cases, tests/gpu/lod_test.cpp,
# through ctest: CUDA vs CPU on the 13-copy city with its LOD).
#
# On the build machine, once (as for gpu_run.sh): scripts/gpu_run.sh prepare
# On the GPU machine, carry [".carry"]:
#   scripts/gpu_lod_run.sh [--prebuilt] [STAGE...]   stages: tests city13 city101 city201
#                                                    (default: all four, in that order)
#   1. builds catgs-bench, catgs-gpu-tests and catgs-scene on the machine (gpu_run.sh's build
#      step: gpu_run.sh --no-tests --no-bench), unless --prebuilt (the binaries in .carry/bin);
#   2. the stages -> $OUT/lod_tests.md, $OUT/lod_cityN.json (catgs-bench's JSON: per variant
#      mean/median/p99 ms, the list, visible Gaussians, device_memory_used_bytes (cudaMemGetInfo
#      after the variant ran, less before the scene), lod_quality_vs_full_detail; top level:
#      scene_device_bytes, lod.build_s, lod.level_chunks) and $OUT/lod_table.md (one row per
#      city x variant x bound, made from those JSONs). Everything printed goes to $OUT/lod.log.
#   A stage that would start after $CATGS_LOD_BUDGET_S seconds (default 540) of the call is
#   skipped with a line saying so (the device gives a call 10 minutes): run it in a second call.
# Exit status: non-zero if a stage failed.
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
CARRY=$ROOT/.carry
OUT=${OUT:-$ROOT/out/gpu_lod}
BUDGET=${CATGS_LOD_BUDGET_S:-540}
# The bounds (1080p pixels) each city runs at: 0 (full detail), the default 1, and around 2,
# where the kd-cluster build keeps 35 dB on the CPU fly-over (1 at 540p, docs/history/level_of_detail.md).
BOUNDS=${CATGS_LOD_BOUNDS:-0,1,1.5,2,2.5,4}
AA=${CATGS_LOD_AA:-0}
PIPES=${CATGS_LOD_PIPES:-exact,catgs}
AA_ARGS=()
[ "$AA" != 0 ] && AA_ARGS=(--aa-reference "$AA")
mkdir -p "$OUT"
exec > >(tee -a "$OUT/lod.log") 2>&1

PREBUILT=0
[ "${1:-}" = --prebuilt ] && { PREBUILT=1; shift; }
echo "== gpu_lod_run.sh $(date -u +%FT%TZ) $(nproc) cores, $(free -g | awk '/Mem:/{print $2}') GiB"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader 2>/dev/null || echo "no nvidia-smi"

if [ "$PREBUILT" = 1 ]; then
  BIN=$CARRY/bin
  export LD_LIBRARY_PATH=$BIN/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
else
  OUT=$OUT/build scripts/gpu_run.sh --no-tests --no-bench || { echo "build failed (see $OUT/build/)"; exit 1; }
  BIN=$ROOT/build/gpu/bin
fi
S=$CARRY/scenes T=$CARRY/traces
TUMBLE=$S/tumblewood_sh2.compressed.ply

lod_tests() (  # the gpu.Lod.* tests -> $OUT/lod_tests.md (ctest; with --prebuilt, the binary alone)
  local rows=$ROOT/build/lod_tests.rows
  rm -f "$rows" "$OUT/lod_tests.md"
  export CATGS_GPU_SCENES=$S CATGS_GPU_TRACES=$T CATGS_GPU_STRICT=1 CATGS_GPU_OUT=$OUT/lod_tests.md
  if [ "$PREBUILT" = 1 ]; then
    "$BIN/catgs-gpu-tests" --gtest_filter='Lod.*'
  else
    CATGS_GPU_ROWS=$rows ctest --test-dir "$ROOT/build/gpu" -L gpu -R '^gpu\.Lod\.' --output-on-failure
  fi
)

city() {  # city NAME RADIUS_SQ
  "$BIN/catgs-bench" --scene "$TUMBLE" --city --radius-sq "$2" --up 0,-1,0 --lod --lod-error "$BOUNDS" \
    --trace flyover --width 1920 --height 1080 --pipeline "$PIPES" --warmup 30 --frames 300 \
    --quality-every 10 "${AA_ARGS[@]}" --json "$OUT/lod_$1.json"
}

stages=("$@")
[ "${#stages[@]}" -gt 0 ] || stages=(tests city13 city101 city201)
status=0
for s in "${stages[@]}"; do
  if [ "$SECONDS" -ge "$BUDGET" ]; then
    echo "== stage $s SKIPPED: $SECONDS s into the call (budget $BUDGET s); run it in a call of its own"
    status=1
    continue
  fi
  t0=$SECONDS
  case "$s" in
    tests) lod_tests ;;
    city13) city city13 4 ;;
    city101) city city101 32 ;;
    city201) city city201 64 ;;
    *) echo "unknown stage '$s' (tests, city13, city101, city201)"; false ;;
  esac || { echo "stage $s FAILED"; status=1; }
  echo "== stage $s: $((SECONDS - t0)) s"
done

# One table over the cities' JSONs (python3 is on the GPU machine).
python3 - "$OUT" > "$OUT/lod_table.md" <<'PY' || status=1
import glob, gzip, json, os, sys
out = sys.argv[1]  # lod_cityN.json, or lod_cityN.json.gz as kept under tests/gpu/results
print("| city | Gaussians (with LOD) | LOD build s | device MiB (scene) | variant | mean ms | p99 ms | "
      "visible | list | PSNR vs full detail mean / min dB | device MiB used | "
      "PSNR vs anti-aliased reference mean / min dB (full detail's) |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
for path in sorted(glob.glob(os.path.join(out, "lod_city*.json*")),
                   key=lambda p: int(p.removesuffix(".gz").split("city")[-1][:-5])):
    j = json.load(gzip.open(path, "rt") if path.endswith(".gz") else open(path))
    for p in j.get("pipelines", []):
        q = p.get("lod_quality_vs_full_detail", {})
        psnr = "%s / %s" % (("%.2f" % q["psnr_db_mean_finite"]) if q.get("compared", 0) > q.get("identical", 0) else "inf",
                            ("%.2f" % q["psnr_db_min"]) if q.get("compared", 0) > q.get("identical", 0) else "inf") if q else "-"
        a = p.get("quality_vs_aa_reference")
        aa = ("%.2f / %.2f (%.2f / %.2f)" % (a["psnr_db_mean_finite"], a["psnr_db_min"],
                                            a["full_detail_psnr_db_mean_finite"], a["full_detail_psnr_db_min"])) if a else "-"
        print("| %s | %d | %.1f | %.0f | %s | %.3f | %.3f | %.0f | %.0f | %s | %.0f | %s |" % (
            os.path.basename(path).removesuffix(".gz")[4:-5], j["gaussians"], j.get("lod", {}).get("build_s", 0),
            j["scene_device_bytes"] / 2**20, p["pipeline"], p["frame_ms"]["mean"], p["frame_ms"]["p99"],
            p.get("visible_mean", 0), p["render_list"]["mean"], psnr, p.get("device_memory_used_bytes", 0) / 2**20, aa))
PY
cat "$OUT/lod_table.md"
echo "== done: status $status in $SECONDS s"
exit $status
