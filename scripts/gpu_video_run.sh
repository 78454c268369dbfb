#!/usr/bin/env bash
# scripts/gpu_video_run.sh: catgs-render --video on a GPU machine (issue 38, item 1): a real
# camera path over a real scene rendered by the CUDA core to H.264 in MP4 at 3840x2160, 60 fps,
# timed, with x264 at two presets (the encoder, on the host's CPUs, is the part that costs).
#
# The GPU machine has no FFmpeg: catgs-render travels prebuilt with its shared libraries (its ldd
# closure minus glibc and the C++ runtime), as scripts/gpu_server_run.sh does for the server.
# On the build machine (after `cmake --preset cuda && cmake --build build/cuda --target
# catgs-render catgs-scene`):
#   scripts/gpu_video_run.sh prepare [BUILD_DIR]   -> .carry_video/ (git-ignored)
# On the GPU machine, carry [".carry_video"]:
#   scripts/gpu_video_run.sh run [FRAMES]          (default 600: 10 s of video)
#     -> $OUT/video.log, $OUT/video.json (frames, seconds, frames/s and bytes per run), and the
#        first 2 s (at most FRAMES) of the video as $OUT/tour_4k60_2s.mp4
# CATGS_RENDERER=cpu runs it with the CPU renderer (to try the script without a GPU; slow).
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
DIR=/tmp/catgs_video
DATA=${CATGS_DATA_DIR:-$ROOT/../shared/data}

prepare() {
  local build=${1:-build/cuda}
  local carry=$ROOT/.carry_video
  rm -rf "$carry" && mkdir -p "$carry/stage/bin" "$carry/stage/lib"
  [ -x "$build/bin/catgs-render" ] || { echo "prepare: $build/bin/catgs-render missing" >&2; return 1; }
  cp -f "$build/bin/catgs-render" "$carry/stage/bin/" && strip "$carry/stage/bin/catgs-render"
  ldd "$build/bin/catgs-render" | awk '/=> \//{print $3}' | sort -u |
    grep -Ev '/(libc|libm|libdl|librt|libpthread|libresolv|libutil|libstdc\+\+|libgcc_s)\.so' |
    while read -r lib; do cp -fL "$lib" "$carry/stage/lib/"; done
  strip --strip-unneeded "$carry"/stage/lib/* 2>/dev/null || true
  # The scene and a real hand-held path fitted to it (the Mip-NeRF 360 bicycle capture's camera
  # motion around the guitar), 60 poses a second at 4K.
  cp -f "$DATA/scenes/guitar.compressed.ply" "$carry/stage/"
  "$build/bin/catgs-scene" trace --scene "$DATA/scenes/guitar.compressed.ply" \
    --cameras "$DATA/traces/mipnerf360_bicycle.cameras.json" --out "$carry/stage/guitar_bicycle.trace" \
    --rate 60 --frames 1200 --width 3840 --height 2160 || return 1
  tar -C "$carry/stage" -cf - . | xz -T2 -6 > "$carry/video.tar.xz"
  rm -rf "$carry/stage"
  du -sh "$carry"
}

run() {
  local frames=${1:-600}
  OUT=${OUT:-$ROOT/out}
  mkdir -p "$OUT"
  exec > >(tee "$OUT/video.log") 2>&1
  rm -rf "$DIR" && mkdir -p "$DIR" && xz -dc "$ROOT/.carry_video/video.tar.xz" | tar -C "$DIR" -xf - || return 1
  export LD_LIBRARY_PATH=$DIR/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  # The first FRAMES poses of the path (the header is 2 lines).
  head -n $((frames + 2)) "$DIR/guitar_bicycle.trace" > "$DIR/path.trace"
  nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || true
  echo "host: $(nproc) cores"
  local json="[" sep=""
  for preset in medium veryfast; do
    local log=$DIR/render_$preset.log
    "$DIR/bin/catgs-render" --scene "$DIR/guitar.compressed.ply" --trace "$DIR/path.trace" \
      --renderer "${CATGS_RENDERER:-cuda}" --pipeline exact --video "$DIR/tour_$preset.mp4" \
      --width 3840 --height 2160 --fps 60 --preset "$preset" 2> "$log"
    local status=$?
    cat "$log"
    # "wrote PATH: N frames, WxH at F fps (S s), BYTES bytes, in T s"
    local line n bytes secs
    line=$(grep '^wrote ' "$log" | tail -1)
    n=$(sed -n 's/.*: \([0-9]*\) frames,.*/\1/p' <<< "$line")
    bytes=$(sed -n 's/.*, \([0-9]*\) bytes,.*/\1/p' <<< "$line")
    secs=$(sed -n 's/.* in \([0-9.]*\) s$/\1/p' <<< "$line")
    json+="$sep{\"preset\": \"$preset\", \"status\": $status, \"frames\": ${n:-0}, \"bytes\": ${bytes:-0}, \"seconds\": ${secs:-0}}"
    sep=", "
  done
  echo "$json]" > "$OUT/video.json"
  cat "$OUT/video.json"
  # A 2 s clip of the medium-preset path to look at (the whole file can pass the 64 MiB limit).
  head -n $((frames < 120 ? frames + 2 : 122)) "$DIR/path.trace" > "$DIR/clip.trace"
  "$DIR/bin/catgs-render" --scene "$DIR/guitar.compressed.ply" --trace "$DIR/clip.trace" \
    --renderer "${CATGS_RENDERER:-cuda}" --video "$OUT/tour_4k60_2s.mp4" --width 3840 --height 2160 --fps 60
}

case "${1:-}" in
  prepare) shift; prepare "$@" ;;
  run) shift; run "$@" ;;
  *) echo "usage: $0 prepare [BUILD_DIR] | run [FRAMES]" >&2; exit 2 ;;
esac
