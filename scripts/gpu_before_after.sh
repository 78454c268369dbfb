#!/usr/bin/env bash
# scripts/gpu_before_after.sh: an earlier commit and the working tree side by side on one GPU, in
# one device call, for changes that must not change images, render lists or speed (refactors).
#
# On the build machine:
#   scripts/gpu_run.sh prepare                      # .carry/: scenes, traces, GLM and friends
#   git archive --format=tar.gz -o .carry/before_src.tar.gz REV
#   (BEFORE_TAR=FILE BEFORE_DIR=DIR on the GPU machine: another earlier tree, a variant, say)
# On the GPU machine (device tool; carry [".carry"]):
#   scripts/gpu_before_after.sh tests               # GPU tests of both builds -> $OUT/gpu_tests_{before,after}.md
#                                                   # (TEST_ARGS=--skip-large: without the 8192-px, 2^31 and city rows)
#   scripts/gpu_before_after.sh bench [FRAMES]      # catgs-bench of both (PIPES=...), alternating per scene x path,
#                                                   # snapshots and per-frame render lists compared
#                                                   # (PATHS=...: the real paths and the city's flyover)
#                                                   # -> $OUT/before_after.md, $OUT/before_after.tar.gz
#   scripts/gpu_before_after.sh scale [FRAMES]      # issue 19's scale rows: the city of 13, 49 and 101 copies
#                                                   # (--radius-sq 4, 16, 32) on the fly-over and the centre view,
#                                                   # both builds alternating (default 300 frames; COPIES=...)
#                                                   # -> $OUT/scale_before_after.md, $OUT/scale.tar.gz
# Both builds use the same flags; the earlier tree keeps its own layout (binaries found by name).
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD CARRY=$PWD/.carry OUT=${OUT:-$PWD/out/before_after}
mkdir -p "$OUT"
export PATH=/usr/local/cuda/bin:$PATH PKG_CONFIG_PATH=$CARRY/deps/lib/pkgconfig
command -v pkg-config >/dev/null || export PATH=$PATH:$CARRY/deps/bin

build() {  # build SRC_DIR LABEL: configures and builds catgs-bench and catgs-gpu-tests
  cmake -S "$1" -B "$1/build/gpu" -G Ninja -DCMAKE_BUILD_TYPE=Release -DWITH_CUDA=ON \
    -DCMAKE_CUDA_COMPILER=/usr/local/cuda/bin/nvcc -DCMAKE_CUDA_ARCHITECTURES=90 -DCATGS_BUILD_SERVER=OFF \
    -DCATGS_BUILD_TESTS=OFF -DCMAKE_PREFIX_PATH="$CARRY/deps" > "$OUT/build_$2.log" 2>&1 &&
    ninja -C "$1/build/gpu" catgs-bench catgs-gpu-tests >> "$OUT/build_$2.log" 2>&1
}
exe() { find "$1/build/gpu" -type f -name "$2" -perm -u+x | head -1; }

# The earlier tree: BEFORE_TAR (default .carry/before_src.tar.gz) unpacked into BEFORE_DIR, kept
# while the machine stays warm, so a second call rebuilds nothing; another BEFORE_TAR and
# BEFORE_DIR put a variant of the working tree beside it in the same call.
BEFORE=${BEFORE_DIR:-/tmp/before_src}
if [ ! -d "$BEFORE/build/gpu" ]; then
  mkdir -p "$BEFORE" && tar xzf "${BEFORE_TAR:-$CARRY/before_src.tar.gz}" -C "$BEFORE" || exit 2
fi
build "$BEFORE" before & build "$ROOT" after & wait
for side in before after; do
  tail -1 "$OUT/build_$side.log"
done
B_BENCH=$(exe "$BEFORE" catgs-bench) A_BENCH=$(exe "$ROOT" catgs-bench)
B_TESTS=$(exe "$BEFORE" catgs-gpu-tests) A_TESTS=$(exe "$ROOT" catgs-gpu-tests)
[ -x "$B_BENCH" ] && [ -x "$A_BENCH" ] || { echo "build failed"; tail -30 "$OUT"/build_*.log; exit 2; }
S=$CARRY/scenes T=$CARRY/traces
status=0

if [ "${1:-}" = tests ]; then
  for side in before after; do
    t=$B_TESTS; [ $side = after ] && t=$A_TESTS
    t0=$(date +%s)
    "$t" --scenes "$S" --traces "$T" --out "$OUT/gpu_tests_$side.md" ${TEST_ARGS:-} | tail -1
    echo "== GPU tests ($side): rc ${PIPESTATUS[0]} in $(( $(date +%s) - t0 )) s"
  done
  python3 "$ROOT/scripts/compare_runs.py" tests "$OUT/gpu_tests_before.md" "$OUT/gpu_tests_after.md" | tee "$OUT/tests_before_after.md"
  exit 0
fi

if [ "${1:-}" = scale ]; then
  FRAMES=${2:-300}
  J=/tmp/ba_scale; rm -rf "$J"; mkdir -p "$J"
  for r2 in ${COPIES:-4 16 32}; do
    for trace in flyover centre; do
      for side in ${ORDER:-before after}; do
        b=$B_BENCH; [ $side = after ] && b=$A_BENCH
        mkdir -p "$J/snap_${side}_city-r${r2}_$trace"
        echo "== $side: city --radius-sq $r2, $trace"
        "$b" --scene "$S/tumblewood_sh2.compressed.ply" --city --radius-sq "$r2" --up 0,-1,0 --trace "$trace" \
          --width 1920 --height 1080 --pipeline "${PIPES:-exact,catgs}" --frames "$FRAMES" \
          --json "$J/${side}_city-r${r2}_$trace.json" --snapshot-dir "$J/snap_${side}_city-r${r2}_$trace" \
          > "$J/${side}_city-r${r2}_$trace.log" 2>&1 || status=1
      done
    done
  done
  python3 "$ROOT/scripts/compare_runs.py" bench "$J" | tee "$OUT/scale_before_after.md"
  tar czf "$OUT/scale.tar.gz" -C "$J" .
  exit $status
fi

FRAMES=${2:-600}
PIPES=${PIPES:-exact,catgs,catgs-nocache,catgs-nosplit}
J=/tmp/ba; rm -rf "$J"; mkdir -p "$J"
for path in ${PATHS:-mipnerf360_bicycle tandt_train flowers_sh3 flyover}; do
  for scene in tumblewood city; do
    size=(--scale 10); [ $scene = city ] && size=(--city)
    trace=real:$T/$path.cameras.json; [ $path = flyover ] && trace=flyover
    [ $path = flyover ] && [ $scene != city ] && continue  # the fly-over is the city's
    for side in ${ORDER:-before after}; do  # alternating, on the same frames (ORDER="after before" swaps)
      b=$B_BENCH; [ $side = after ] && b=$A_BENCH
      mkdir -p "$J/snap_${side}_${scene}_$path"
      echo "== $side: $scene, $path"
      "$b" --scene "$S/tumblewood_sh2.compressed.ply" "${size[@]}" --up 0,-1,0 \
        --trace "$trace" --width 1920 --height 1080 --pipeline "$PIPES" \
        --frames "$FRAMES" --quality-every 3 --json "$J/${side}_${scene}_$path.json" \
        --snapshot-dir "$J/snap_${side}_${scene}_$path" > "$J/${side}_${scene}_$path.log" 2>&1 || status=1
    done
  done
done
python3 "$ROOT/scripts/compare_runs.py" bench "$J" | tee "$OUT/before_after.md"
tar czf "$OUT/before_after.tar.gz" -C "$J" .
exit $status
