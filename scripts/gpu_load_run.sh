#!/usr/bin/env bash
# scripts/gpu_load_run.sh: issue 37's scene-loading table on the GPU machine (16 cores): plain and
# cached loads, cold and warm page cache, peak memory and the upload to the GPU, for biker,
# flowers, tumblewood and the 13- and 101-copy cities (catgs-scene load-bench --upload).
#
# On the build machine, once: build the CUDA preset (its catgs-scene links the CUDA core, which
# --upload needs) and fill .carry/:
#   cmake --preset cuda && cmake --build build/cuda --target catgs-scene catgs-bench catgs-gpu-tests
#   scripts/gpu_run.sh prepare
# On the GPU machine, carry [".carry"]:
#   scripts/gpu_load_run.sh [STAGE...]      stages: small city13 build101 city101 (default: small city13)
#     small    biker (compressed PLY, bundled), flowers_sh3 (INRIA PLY, SH 3), tumblewood_sh2 as
#              INRIA PLY (88.9 MB, decoded from the carried compact copy: the original does not
#              fit the carry; same size and layout, values quantised)
#     city13   the 13-copy city (7.05 M Gaussians, INRIA PLY, 1.16 GB), built from the compact
#              tumblewood (catgs-scene tile, as gpu_server_run.sh's scenes)
#     build101 builds the 101-copy city (54.8 M, 9.0 GB; --radius-sq 32) on the machine, nothing
#              else (a few minutes: a call of its own, the next one right after it while the
#              machine is warm)
#     city101  its table (builds it first when missing), one warm load a row, no serial reference
#   -> $OUT/load_STAGE.json and .md (the tables), $OUT/load.log. Scenes and caches go to
#   $CATGS_LOAD_DIR (default /tmp/catgs_load) and stay for the next call while the machine is
#   warm. The log records that folder's file system: on tmpfs "cold" equals "warm" (the file is
#   memory), so point CATGS_LOAD_DIR at a disk for cold rows that mean something.
#   CATGS_LOAD_UPLOAD=0 leaves the upload out (to try the script with a CPU-only catgs-scene).
#   CATGS_LOAD_TOOL=PATH runs another catgs-scene (an earlier commit's, side by side), its tables
#   named with CATGS_LOAD_TAG appended (load_city13_before.json).
# Exit status: non-zero if a stage failed.
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
CARRY=$ROOT/.carry
OUT=${OUT:-$ROOT/out/gpu_load}
W=${CATGS_LOAD_DIR:-/tmp/catgs_load}
mkdir -p "$OUT" "$W"
exec > >(tee -a "$OUT/load.log") 2>&1

TOOL=${CATGS_LOAD_TOOL:-$CARRY/bin/catgs-scene}  # another build side by side: CATGS_LOAD_TOOL, CATGS_LOAD_TAG
export LD_LIBRARY_PATH=$CARRY/bin/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
[ -x "$TOOL" ] || { echo "gpu_load_run.sh: $TOOL missing (scripts/gpu_run.sh prepare on the build machine)"; exit 1; }
TUMBLE=$CARRY/scenes/tumblewood_sh2.compressed.ply

echo "== $(date -u +%FT%TZ) $(nproc) cores, $(free -g | awk '/Mem:/{print $2}') GiB"
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader 2>/dev/null || echo "no nvidia-smi"
df -hT "$W" | tail -1

bench() {  # bench NAME ARGS... : load-bench over the scenes, table to NAME.md
  local name=$1
  shift
  local upload=()
  [ "${CATGS_LOAD_UPLOAD:-1}" = 0 ] || upload=(--upload)
  name=$name${CATGS_LOAD_TAG:-}
  "$TOOL" load-bench "${upload[@]}" --json "$OUT/load_$name.json" "$@" | tee "$OUT/load_$name.md"
  return "${PIPESTATUS[0]}"
}

small() {
  [ -f "$W/tumblewood_sh2.ply" ] || "$TOOL" convert --scene "$TUMBLE" --out "$W/tumblewood_sh2.ply" || return 1
  cp -f "$ROOT/assets/scenes/biker.compressed.ply" "$CARRY/scenes/flowers_sh3.ply" "$W/"
  bench small --scenes "$W/biker.compressed.ply,$W/flowers_sh3.ply,$W/tumblewood_sh2.ply" --repeat 5
}

build_city() {  # build_city NAME RADIUS_SQ
  local name=$1 r=$2
  if [ ! -f "$W/$name.ply" ]; then
    local t0=$SECONDS
    "$TOOL" tile --scene "$TUMBLE" --scale 10 --radius-sq "$r" --up 0,-1,0 --out "$W/$name.ply" > "$W/$name.tile.log" ||
      { cat "$W/$name.tile.log"; return 1; }
    head -1 "$W/$name.tile.log"
    echo "$name: built in $((SECONDS - t0)) s, $(du -h "$W/$name.ply" | cut -f1)"
  fi
}

city() {  # city NAME RADIUS_SQ BENCH_ARGS...
  local name=$1 r=$2
  shift 2
  build_city "$name" "$r" || return 1
  bench "$name" --scenes "$W/$name.ply" "$@"
}

stages=("$@")
[ "${#stages[@]}" -gt 0 ] || stages=(small city13)
status=0
for s in "${stages[@]}"; do
  t0=$SECONDS
  case "$s" in
    small) small ;;
    city13) city city13 4 --repeat 3 ;;
    build101) build_city city101 32 ;;
    city101) city city101 32 --repeat 1 --no-reference ;;
    *) echo "unknown stage '$s' (small, city13, build101, city101)"; false ;;
  esac || { echo "stage $s FAILED"; status=1; }
  echo "== stage $s: $((SECONDS - t0)) s"
done
exit $status
