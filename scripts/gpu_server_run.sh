#!/usr/bin/env bash
# scripts/gpu_server_run.sh: the streaming server on a GPU machine (issue 5).
#
# The GPU machine has no libwebsockets, FFmpeg or protobuf, so the server, catgs-loadgen and the
# server's unit tests travel prebuilt with the shared libraries they need (their ldd closure
# minus glibc and the C++ runtime, about 45 MB as tar.xz). That and the scenes of gpu_run.sh do
# not fit one run's 64 MiB, hence two runs back to back on the same warm machine:
#
# On the build machine, once (after `cmake --preset cuda -DCATGS_VIDEO_EXPORT=OFF && cmake --build
# build/cuda`; with video export ON the server also brings libavformat's closure, 34 more
# libraries, +6.4 MB as xz, which leaves the two runs' carry about 1 MiB under 64 MiB):
#   scripts/gpu_server_run.sh prepare [BUILD_DIR]      -> .carry_srv/ (git-ignored)
# On the GPU machine:
#   1. carry [".carry_srv"]:  scripts/gpu_server_run.sh check
#        unpacks everything under /tmp/catgs_srv; runs the server unit tests (NVENC's failure path
#        with a real NVIDIA driver); starts catgs-server --renderer cuda --pipeline catgs on the
#        bundled biker scene and runs 4 catgs-loadgen sessions (different sizes and paths) that
#        decode every frame and compare every 4th with the CPU reference render of its pose
#        (PSNR >= 30 dB) -> $OUT/server_check.log, $OUT/check.json
#   2. within the machine's warm period, carry [".carry"] (scripts/gpu_run.sh prepare):
#        scripts/gpu_server_run.sh sweep [--seconds S] [--counts "1 2 4 8 16"] [--sizes "..."]
#          [--pipeline catgs|exact|vanilla] [--city-counts "..."] [--server-arg ARG]...
#        1, 2, 4, 8, 16 sessions at 1280x720 and 1920x1080 on tumblewood_sh2 (x10) and the
#        13-copy city (~7 M), real camera paths in turn, 60 poses/s per session, x264 (auto:
#        NVENC if the GPU has it), no client decode; CPU and GPU utilisation sampled
#        -> $OUT/sweep.md (table), $OUT/sweep.tar.gz (every loadgen JSON), $OUT/sweep.log
# The encoder policy's measurements (issue 35), carry [".carry_srv"] alone (it holds the compact
# tumblewood scene): `unpack`, `scenes` (tumblewood x10, the 13-copy city, the real paths
# fitted), `rd SCENE WxH SETTINGS` (catgs-encode-bench), `captures` and `rdtrace FILE TRACE WxH
# SETTINGS FRAMES TAG` (the real captures, issue 51), `ramp NAME SCENE WxH PIPELINE START STEP
# MAX P95_MS MIN_FPS [SERVER ARGS]` (sessions until a bound breaks; scripts/ramp_table.py);
# the level of detail in the server (issue 46): `bigcity R NAME` (49 or 101 copies) and
# `firstframe NAME SCENE WxH [SERVER ARGS]` (start to listening, the first session's frames),
# `pictures SCENE WxH BOUNDS [BENCH ARGS]` (catgs-bench's yardstick and PNGs of full detail, the
# cut and the supersampled render); the compact scene (issue 74): `compactcity R NAME`,
# `compactcopy NAME`, `readrate FILE` (a scene NAME.catgs is served in place of
# NAME.compressed.ply where it exists); `hogramp NAME SCENE WxH HOG_GIB START STEP MAX [SERVER ARGS]` (issue 73: the
# ramp beside another process that holds HOG_GIB GiB of the GPU).
# The shown-picture measure (issue 91; prepare with CATGS_CARRY_SHOWN=1): `shown NAME SCENE WxH
# LOADED [SERVER ARGS]`; catgs-loadgen's own CPU, the landed binary beside this one (issue 92;
# prepare with CATGS_CARRY_BINS=PATH/landed/catgs-loadgen): `clientcpu NAME SCENE N`.
# Headsets (issue 94): `stereocost NAME SCENE EWxEH HZ [SERVER ARGS]` (a stereo frame's GPU time
# against a mono frame of one eye), and `ramp` with CATGS_LOADGEN_ARGS="--stereo EWxEH@HZ".
# CATGS_RENDERER=cpu makes both use the CPU renderer (to try the script on a machine without GPU).
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
SRV=${CATGS_SRV:-/tmp/catgs_srv}  # CATGS_SRV: another unpacked build (a before/after pair)

prepare() {
  local build=${1:-build/cuda}
  local carry=$ROOT/.carry_srv
  rm -rf "$carry" && mkdir -p "$carry/stage/bin" "$carry/stage/lib"
  # catgs-encode-bench (rd) and catgs-bench (pictures) only when asked: with the rest and the
  # scene they would pass the carry's 64 MiB.
  # CATGS_CARRY_TESTS=0 leaves the server's unit tests (`check`) out for room.
  # CATGS_CARRY_SERVER=0 leaves the server and catgs-loadgen out (an `rd`-only carry).
  local bins=("$build/bin/catgs-scene")
  [ "${CATGS_CARRY_SERVER:-1}" = 1 ] && bins+=("$build/bin/catgs-server" "$build/bin/catgs-loadgen")
  [ "${CATGS_CARRY_TESTS:-1}" = 1 ] && bins+=("$(find "$build" -type f -name catgs_server_unit_tests -perm -u+x | head -1)")
  [ "${CATGS_CARRY_ENCODE_BENCH:-0}" = 1 ] && bins+=("$build/bin/catgs-encode-bench")
  [ "${CATGS_CARRY_BENCH:-0}" = 1 ] && bins+=("$build/bin/catgs-bench")
  # catgs-shown (issue 91's measure: `shown`), and any other binaries named in CATGS_CARRY_BINS
  # (space-separated paths, e.g. the landed build's catgs-loadgen for `clientcpu`).
  [ "${CATGS_CARRY_SHOWN:-0}" = 1 ] && bins+=("$build/bin/catgs-shown")
  # shellcheck disable=SC2206
  [ -n "${CATGS_CARRY_BINS:-}" ] && bins+=(${CATGS_CARRY_BINS})
  # The other process of hogramp (built with the GPU tests), where built.
  [ -x "$build/bin/catgs-memory-hog" ] && bins+=("$build/bin/catgs-memory-hog")
  for b in "${bins[@]}"; do
    [ -x "$b" ] || { echo "prepare: $b missing (build $build with the server)" >&2; return 1; }
    # A binary from another build keeps the name of its folder's tag: .../landed/catgs-loadgen
    # travels as catgs-loadgen-landed.
    case "$b" in
      "$build"/*) cp -f "$b" "$carry/stage/bin/" ;;
      *) cp -f "$b" "$carry/stage/bin/$(basename "$b")-$(basename "$(dirname "$b")")" ;;
    esac
  done
  strip "$carry"/stage/bin/* 2>/dev/null || true
  if ldd "${bins[@]}" | grep -q libavformat; then
    echo "prepare: note: this catgs-server has video export (libavformat, +6.4 MB xz in the carry);" \
      "configure $build with -DCATGS_VIDEO_EXPORT=OFF for a smaller one" >&2
  fi
  # Every shared library they load, except glibc's and the C++ runtime (the GPU machine's newer
  # ones serve binaries built against older ones; mixing glibc versions would not work).
  ldd "${bins[@]}" | awk '/=> \//{print $3}' | sort -u |
    grep -Ev '/(libc|libm|libdl|librt|libpthread|libresolv|libutil|libstdc\+\+|libgcc_s)\.so' |
    while read -r lib; do cp -fL "$lib" "$carry/stage/lib/"; done
  strip --strip-unneeded "$carry"/stage/lib/* 2>/dev/null || true
  # ICU's 30 MB of locale data (libicudata, pulled in through libxml2 by FFmpeg's dependencies)
  # is never read by the server: a stub that defines only its data symbol keeps the loader happy
  # and the carry under 64 MiB (the xz grows by about 9 MB with the real one).
  local icu
  for icu in "$carry"/stage/lib/libicudata.so.*; do
    [ -f "$icu" ] || continue
    local ver=${icu##*.so.}
    echo "const char icudt${ver%%.*}_dat[16] = {0};" |
      gcc -shared -x c - -o "$icu" -Wl,-soname,"$(basename "$icu")" || return 1
  done
  # -9e: 1.5 MB smaller than -6 (1.5 min on 2 cores), room for catgs-bench under the 64 MiB.
  tar -C "$carry/stage" -cf - bin lib | xz -T2 -9e > "$carry/server.tar.xz"
  rm -rf "$carry/stage"
  mkdir -p "$carry/traces"
  cp -f "${CATGS_DATA_DIR:-$ROOT/../shared/data}"/traces/*.cameras.json "$carry/traces/"
  # The scene of `scenes` (tumblewood x10 and the 13-copy city are made from it on the GPU
  # machine): the compact copy gpu_run.sh prepare makes, or made here; xz keeps the carry under
  # 64 MiB (22 -> 12.5 MB).
  mkdir -p "$carry/scenes"
  local tw=$ROOT/.carry/scenes/tumblewood_sh2.compressed.ply
  if [ ! -f "$tw" ]; then
    tw=$carry/scenes/tumblewood_sh2.compressed.ply
    "$build/bin/catgs-scene" compact --scene "${CATGS_DATA_DIR:-$ROOT/../shared/data}/scenes/tumblewood_sh2.ply" \
      --out "$tw" --up 0,-1,0 || return 1
  fi
  xz -T2 -6 -c "$tw" > "$carry/scenes/tumblewood_sh2.compressed.ply.xz" && rm -f "$carry/scenes/tumblewood_sh2.compressed.ply"
  du -sh "$carry"
}

unpack() {
  rm -rf "$SRV" && mkdir -p "$SRV" && xz -dc "$ROOT/.carry_srv/server.tar.xz" | tar -C "$SRV" -xf - || return 1
  # The test binaries look for the bundled scene at the build machine's source path.
  mkdir -p /work && [ -e /work/main ] || ln -sfn "$ROOT" /work/main
}

# start_server SCENE LOG ARGS...: starts catgs-server on a free port, sets SERVER_PID and PORT.
# The scene file of NAME under /tmp/catgs_sweep: NAME.catgs (a compact scene, issue 74) where it
# exists, else NAME.compressed.ply.
scene_file() {
  local W=/tmp/catgs_sweep
  if [ -f "$W/$1.catgs" ]; then echo "$W/$1.catgs"; else echo "$W/$1.compressed.ply"; fi
}
start_server() {
  local scene=$1 log=$2
  shift 2
  # The worker pool at its default (one thread per usable core, server/cpu_quota.h), as a deployment
  # runs it; more workers than cores cost sessions (RESULTS.md "Sessions per GPU host"). A
  # --threads among the arguments wins.
  "$SRV/bin/catgs-server" --scene "$scene" --port 0 --renderer "${CATGS_RENDERER:-cuda}" --pipeline catgs \
    --encoder auto --max-sessions 64 --web-root "$ROOT/web_client" "$@" > "$log" 2>&1 &
  SERVER_PID=$!
  PORT=
  for _ in $(seq 1 1500); do
    PORT=$(sed -n 's|.*listening on http://[^:]*:\([0-9]*\)/.*|\1|p' "$log" | head -1)
    [ -n "$PORT" ] && return 0
    kill -0 "$SERVER_PID" 2>/dev/null || { echo "server exited:"; cat "$log"; return 1; }
    sleep 0.2
  done
  echo "server did not listen in 300 s"; cat "$log"; return 1
}

stop_server() {
  kill -INT "$SERVER_PID" 2>/dev/null  # SIGINT stops at once; SIGTERM would drain open sessions
  wait "$SERVER_PID" 2>/dev/null
}

check() {
  exec > >(tee "$OUT/server_check.log") 2>&1
  echo "== gpu_server_run.sh check $(date -u +%FT%TZ)"
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
  unpack || { echo "unpack failed"; return 1; }
  export LD_LIBRARY_PATH=$SRV/lib
  local status=0
  echo "== server unit tests (encoders with a real NVIDIA driver, metrics, loadgen report)"
  "$SRV/bin/catgs_server_unit_tests" --gtest_brief=1 || status=1
  echo "== catgs-server --renderer cuda, 4 sessions, decoded frames vs the CPU reference"
  local scene=$ROOT/assets/scenes/biker.compressed.ply T=$ROOT/.carry_srv/traces
  start_server "$scene" "$OUT/server_check_server.log" || return 1
  "$SRV/bin/catgs-loadgen" --port "$PORT" --sessions 4 --scene "$scene" \
    --size 640x360,960x540,800x600,1280x720 \
    --trace "orbit,real:$T/tandt_train.cameras.json,real:$T/mipnerf360_bicycle.cameras.json,real:$T/flowers_sh3.cameras.json" \
    --rate 60 --seconds 6 --check-every 4 --check-min-psnr 30 --json "$OUT/check.json" || status=1
  echo "== /metrics (excerpt)"
  python3 -c "import urllib.request,sys; print(urllib.request.urlopen(sys.argv[1]).read().decode())" \
    "http://127.0.0.1:$PORT/metrics" | grep -E "^catgs_(info|encoder_fallbacks|frames_total|render_frames_total|sessions)" | head -20
  stop_server
  echo "== server log (head)"; head -20 "$OUT/server_check_server.log"
  echo "check status: $status"
  return $status
}

sweep() {
  local seconds=6 counts="1 2 4 8 16" city_counts="" sizes="1280x720 1920x1080" pipeline=catgs
  local server_args=()
  while [ $# -gt 0 ]; do
    case "$1" in
      --seconds) seconds=$2; shift ;;
      --counts) counts=$2; shift ;;
      --city-counts) city_counts=$2; shift ;;
      --pipeline) pipeline=$2; shift ;;
      --server-arg) server_args+=("$2"); shift ;;
      --sizes) sizes=$2; shift ;;
      *) echo "sweep: unknown option $1" >&2; return 2 ;;
    esac
    shift
  done
  city_counts=${city_counts:-$counts}
  exec > >(tee "$OUT/sweep.log") 2>&1
  echo "== gpu_server_run.sh sweep $(date -u +%FT%TZ)"
  [ -x "$SRV/bin/catgs-server" ] || { echo "no $SRV: run 'check' first on this machine"; return 1; }
  export LD_LIBRARY_PATH=$SRV/lib:$ROOT/.carry/bin/lib
  local C=$ROOT/.carry W=/tmp/catgs_sweep
  mkdir -p "$W/json"
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | tee "$W/gpu.txt"
  nproc | tee "$W/cores.txt"
  echo "== scenes: tumblewood_sh2 x10 and the 13-copy city"
  make_scenes "$C/bin/catgs-scene" "$C/scenes/tumblewood_sh2.compressed.ply" "$C/traces" || return 1
  local status=0
  for scene in tumblewood city; do
    start_server "$W/$scene.compressed.ply" "$W/server_$scene-$pipeline.log" --pipeline "$pipeline" \
      "${server_args[@]}" || return 1
    local scene_counts=$counts
    [ "$scene" = city ] && scene_counts=$city_counts
    local traces="$W/${scene}_mipnerf360_bicycle.trace,$W/${scene}_tandt_train.trace,$W/${scene}_flowers_sh3.trace"
    for size in $sizes; do
      for n in $scene_counts; do
        local tag=$scene-${pipeline}_${size}_$n
        measure "$tag" "$n" "$size" "$PORT" "$traces" "$seconds" || status=1
        tail -4 "$W/load_$tag.txt" | head -2
        echo "-- $tag done"
      done
    done
    stop_server
  done
  python3 "$ROOT/scripts/sweep_table.py" "$W" > "$OUT/sweep.md"
  tar -C "$W" -czf "$OUT/sweep.tar.gz" json gpu.txt cores.txt $(cd "$W" && ls server_*.log load_*.txt)
  cat "$OUT/sweep.md"
  echo "sweep status: $status"
  return $status
}


# scenes: tumblewood_sh2 x10 and the 13-copy city (~7 M) with the three real camera paths fitted
# to each, under /tmp/catgs_sweep (made once per machine; the `sweep` above makes the same).
scenes() {
  local W=/tmp/catgs_sweep S=$ROOT/.carry_srv
  export LD_LIBRARY_PATH=$SRV/lib
  mkdir -p "$W/json"
  [ -f "$W/city_flowers_sh3.trace" ] && return 0
  xz -dc "$S/scenes/tumblewood_sh2.compressed.ply.xz" > "$W/tumblewood_sh2.compressed.ply" || return 1
  make_scenes "$SRV/bin/catgs-scene" "$W/tumblewood_sh2.compressed.ply" "$S/traces"
}

# make_scenes CATGS_SCENE SOURCE TRACES: tumblewood x10 and the 13-copy city from SOURCE (the
# compact tumblewood_sh2) and the three real paths of TRACES fitted to each, in /tmp/catgs_sweep
# (once per machine).
make_scenes() {
  local tool=$1 src=$2 traces=$3 W=/tmp/catgs_sweep
  mkdir -p "$W/json"
  [ -f "$W/city_flowers_sh3.trace" ] && return 0
  "$tool" compact --scene "$src" --scale 10 --out "$W/tumblewood.compressed.ply" || return 1
  "$tool" tile --scene "$src" --scale 10 --radius-sq 4 --up 0,-1,0 --out-compressed "$W/city.compressed.ply" || return 1
  for scene in tumblewood city; do
    for path in mipnerf360_bicycle tandt_train flowers_sh3; do
      "$tool" trace --scene "$W/$scene.compressed.ply" --cameras "$traces/$path.cameras.json" \
        --out "$W/${scene}_$path.trace" --up 0,-1,0 --frames 1200 || return 1
    done
  done
}

# bigcity RADIUS_SQ NAME: a city of the compact tumblewood's copies on the cells i^2 + j^2 <=
# RADIUS_SQ (16: 49 copies, 32: 101) and the three real paths fitted to it, in /tmp/catgs_sweep
# (after `scenes`; once per machine).
bigcity() {
  local r=$1 name=$2 W=/tmp/catgs_sweep S=$ROOT/.carry_srv
  export LD_LIBRARY_PATH=$SRV/lib
  [ -f "$W/${name}_flowers_sh3.trace" ] && return 0
  "$SRV/bin/catgs-scene" tile --scene "$W/tumblewood_sh2.compressed.ply" --scale 10 --radius-sq "$r" --up 0,-1,0 \
    --out-compressed "$W/$name.compressed.ply" || return 1
  for path in mipnerf360_bicycle tandt_train flowers_sh3; do
    "$SRV/bin/catgs-scene" trace --scene "$W/$name.compressed.ply" --cameras "$S/traces/$path.cameras.json" \
      --out "$W/${name}_$path.trace" --up 0,-1,0 --frames 1200 || return 1
  done
}

# firstframe NAME SCENE WxH [SERVER ARGS...]: seconds from starting catgs-server until it listens
# with SCENE loaded (its LOD file read, or built and written), then one session's first frames
# (catgs-loadgen, 3 s) -> $OUT/firstframe-NAME.log (the server's log and the session's report).
firstframe() {
  local name=$1 scene=$2 size=$3 W=/tmp/catgs_sweep
  shift 3
  export LD_LIBRARY_PATH=$SRV/lib
  local t0 t1
  t0=$(date +%s.%N)
  start_server "$(scene_file "$scene")" "$W/server_first-$name.log" "$@" || return 1
  t1=$(date +%s.%N)
  "$SRV/bin/catgs-loadgen" --port "$PORT" --sessions 1 --size "$size" --trace "$W/${scene}_mipnerf360_bicycle.trace" \
    --rate 60 --seconds 3 --warmup 0 --json "$W/json/first-$name.json" > "$W/first_$name.txt" 2>&1
  stop_server
  { echo "== $name: listening with the scene loaded $(python3 -c "print('%.2f' % ($t1 - $t0))") s after start"
    grep -E "scene|level of detail|LOD|uploaded|loaded|listening" "$W/server_first-$name.log" | head -12
    tail -5 "$W/first_$name.txt"; } | tee "$OUT/firstframe-$name.log"
}

# pictures SCENE WxH BOUNDS [BENCH ARGS]: catgs-bench (prepare with CATGS_CARRY_BENCH=1) on
# SCENE's bicycle path, exact, LOD built, the bounds BOUNDS (e.g. 0,2) timed and scored against
# full detail and a 4x supersampled render; PNGs of the middle pose (each bound, full detail, the
# supersampled reference) -> $OUT/pictures/SCENE_WxH[_TAG]/, the JSON ->
# $OUT/yardstick_SCENE_WxH[_TAG].json (TAG: $CATGS_PICTURES_TAG; e.g. `--compact`, issue 74).
# The scene is SCENE.compressed.ply (not a compact copy: --compact measures the quantization).
pictures() {
  local scene=$1 size=$2 bounds=$3 W=/tmp/catgs_sweep tag=${CATGS_PICTURES_TAG:+_$CATGS_PICTURES_TAG}
  shift 3
  export LD_LIBRARY_PATH=$SRV/lib
  "$SRV/bin/catgs-bench" --scene "$W/$scene.compressed.ply" --lod --trace "$W/${scene}_mipnerf360_bicycle.trace" \
    --renderer cuda --width "${size%x*}" --height "${size#*x}" --pipeline exact --lod-error "$bounds" \
    --frames 120 --warmup 10 --quality-every 12 --aa-reference 4 --snapshot-dir "$OUT/pictures/${scene}_$size$tag" \
    --json "$OUT/yardstick_${scene}_$size$tag.json" "$@"
}

# compactcity R NAME: the city of R (catgs-scene tile) written straight as a compact scene with
# its level of detail, $W/NAME.catgs (issue 74: the 405-copy city fits the GPU machine's disk
# only so), and its three real paths; peak memory and times -> $OUT/compactcity-NAME.log.
compactcity() {
  local r=$1 name=$2 W=/tmp/catgs_sweep S=$ROOT/.carry_srv
  export LD_LIBRARY_PATH=$SRV/lib
  [ -f "$W/${name}_flowers_sh3.trace" ] && return 0
  { /usr/bin/time -f "tile: %e s, peak RSS %M KiB" "$SRV/bin/catgs-scene" tile \
      --scene "$W/tumblewood_sh2.compressed.ply" --scale 10 --radius-sq "$r" --up 0,-1,0 --out-catgs "$W/$name.catgs" |
      grep -v "^  copy"; } 2>&1 | tee "$OUT/compactcity-$name.log" || return 1
  ls -l "$W/$name.catgs" | tee -a "$OUT/compactcity-$name.log"
  for path in mipnerf360_bicycle tandt_train flowers_sh3; do
    "$SRV/bin/catgs-scene" trace --scene "$W/$name.catgs" --cameras "$S/traces/$path.cameras.json" \
      --out "$W/${name}_$path.trace" --up 0,-1,0 --frames 1200 || return 1
  done
}

# compactcopy NAME: NAME's compact scene with its level of detail (catgs-scene lod of
# NAME.compressed.ply; the server then serves it from then on) and the read rate of `dd` on it
# -> $OUT/compactcopy-NAME.log.
compactcopy() {
  local name=$1 W=/tmp/catgs_sweep
  export LD_LIBRARY_PATH=$SRV/lib
  { "$SRV/bin/catgs-scene" lod --scene "$W/$name.compressed.ply" --out "$W/$name.catgs"
    ls -l "$W/$name.compressed.ply" "$W/$name.catgs"; } 2>&1 | tee "$OUT/compactcopy-$name.log"
}

# shown NAME SCENE WxH LOADED [SERVER ARGS]: the shown-picture measure (issue 91) on SCENE's three
# real paths, one session a path in each run of 10 s at 60 poses/s (catgs-loadgen --record):
# `one` on loopback (3 sessions), `loaded` on loopback with LOADED sessions (the first three, the
# same paths and offsets, are scored), `l25` 25 Mbit/s with a 40 ms round trip and `l8` 8 Mbit/s
# with 80 ms (emulated in the client: tools/loadgen/recording.h); each against the server with
# SERVER ARGS and --pose-prediction off (`base`: the landed server's frames) and again with
# --pose-prediction on (`pred`). Then catgs-shown on the GPU
# scores every 3rd refresh (CATGS_SHOWN_EVERY) of all eight against the 4x supersampled
# full-detail render -> $OUT/shown-NAME.txt, .json, each session's worst refresh's pictures in
# $OUT/shown-NAME-pictures.tar, and the runs' loadgen tables in $OUT/shown-NAME-runs.txt.
shown() {
  local name=$1 scene=$2 size=$3 loaded=$4 W=/tmp/catgs_sweep
  shift 4
  local R=/tmp/catgs_shown/$name
  export LD_LIBRARY_PATH=$SRV/lib
  rm -rf "$R" && mkdir -p "$R" "$W/cache"
  local traces="$W/${scene}_mipnerf360_bicycle.trace,$W/${scene}_tandt_train.trace,$W/${scene}_flowers_sh3.trace"
  local config run n runs=""
  # CATGS_SHOWN_CONFIGS: which servers record (base: --pose-prediction off, the landed build's
  # frames; pred: on); CATGS_SHOWN_RUNS: which links (default one loaded l25 l8);
  # CATGS_SHOWN_FLAGS: more rows of catgs-shown (e.g. --depth-warp, --parts); CATGS_SHOWN_BASE:
  # the rows always asked (default --plain --centre-plane; the centre probe runs on the CPU at full
  # detail, most of the scoring's time on a city).
  # `before`: as pred, with the server of another unpacked build (CATGS_SRV_BEFORE: a before/after
  # pair scored in one table).
  for config in ${CATGS_SHOWN_CONFIGS:-base pred}; do
    local extra=(--pose-prediction off) srv=$SRV
    [ "$config" = pred ] || [ "$config" = before ] && extra=(--pose-prediction on)
    [ "$config" = before ] && SRV=${CATGS_SRV_BEFORE:?CATGS_SRV_BEFORE names the before build}
    start_server "$(scene_file "$scene")" "$R/server-$config.log" --cache-dir "$W/cache" "$@" "${extra[@]}" || return 1
    SRV=$srv
    for run in ${CATGS_SHOWN_RUNS:-one loaded l25 l8}; do
      local link=()
      n=3
      case $run in
        loaded) n=$loaded ;;
        l25) link=(--link-rtt-ms 40 --link-mbit 25) ;;
        l8) link=(--link-rtt-ms 80 --link-mbit 8) ;;
      esac
      "$SRV/bin/catgs-loadgen" --port "$PORT" --sessions "$n" --size "$size" --trace "$traces" --rate 60 \
        --seconds 10 --progress 0 --record "$R/$config-$run" --json "$R/$config-$run.json" "${link[@]}" \
        > "$R/$config-$run.txt" 2>&1
      { echo "== $config-$run: $n sessions ${link[*]}"; tail -5 "$R/$config-$run.txt"; depth_share "$R/$config-$run"; } |
        tee -a "$OUT/shown-$name-runs.txt"
      runs="$runs${runs:+,}$config-$run=$R/$config-$run"
    done
    stop_server
  done
  "$SRV/bin/catgs-shown" --scene "$(scene_file "$scene")" --cache-dir "$W/cache" --renderer cuda --run "$runs" \
    --every "${CATGS_SHOWN_EVERY:-3}" ${CATGS_SHOWN_BASE---plain --centre-plane} ${CATGS_SHOWN_FLAGS:-} --json "$OUT/shown-$name.json" --png-dir "$R/pictures" 2>&1 |
    tee "$OUT/shown-$name.txt"
  tar -C "$R" -cf "$OUT/shown-$name-pictures.tar" pictures  # one file: a call brings back 8 at most
}

# threadcpu NAME SCENE N [SERVER ARGS]: where the server's cores go with N sessions at 720p on
# SCENE's three real paths (issue 92): CPU seconds per thread kind (/proc/PID/task/*: catgs-lws,
# catgs-laneK, catgs-poolK, catgs-x264 (x264's sliced threads, named when an encoder opens), the rest) over 8 s in the middle of
# a 12 s run, beside the run's own summary -> $OUT/threadcpu-NAME.txt.
threadcpu() {
  local name=$1 scene=$2 n=$3 W=/tmp/catgs_sweep
  shift 3
  export LD_LIBRARY_PATH=$SRV/lib
  start_server "$(scene_file "$scene")" "$W/server_threadcpu-$name.log" --cache-dir "$W/cache" "$@" || return 1
  local traces="$W/${scene}_mipnerf360_bicycle.trace,$W/${scene}_tandt_train.trace,$W/${scene}_flowers_sh3.trace"
  "$SRV/bin/catgs-loadgen" --port "$PORT" --sessions "$n" --size 1280x720 --trace "$traces" --rate 60 --seconds 12 \
    --progress 0 > "$W/threadcpu-$name-loadgen.txt" 2>&1 &
  local lg=$!
  sleep 3
  python3 - "$SERVER_PID" 8 <<'PY' | tee "$OUT/threadcpu-$name.txt"
import glob, os, re, sys, time
pid, span = sys.argv[1], float(sys.argv[2])
tick = os.sysconf('SC_CLK_TCK')
def sample():
    out = {}
    for d in glob.glob('/proc/%s/task/*' % pid):
        try:
            comm = open(d + '/comm').read().strip()
            f = open(d + '/stat').read().rsplit(')', 1)[1].split()
            out[d] = (comm, (int(f[11]) + int(f[12])) / tick)
        except OSError:
            pass
    return out
a = sample(); time.sleep(span); b = sample()
kinds = {}
for d, (comm, t) in b.items():
    kind = comm if comm == 'catgs-x264' else re.sub(r'\d+$', '', comm)
    k = kinds.setdefault(kind, [0.0, 0])
    k[0] += t - a.get(d, (comm, 0.0))[1]; k[1] += 1
total = sum(v[0] for v in kinds.values())
print('%-16s %8s %8s %7s' % ('thread kind', 'threads', 'CPU s', 'cores'))
for kind, (t, n) in sorted(kinds.items(), key=lambda kv: -kv[1][0]):
    print('%-16s %8d %8.2f %7.2f' % (kind, n, t, t / span))
print('%-16s %8d %8.2f %7.2f' % ('all', sum(v[1] for v in kinds.values()), total, total / span))
PY
  wait "$lg"
  { echo "== catgs-loadgen, $n sessions"; tail -6 "$W/threadcpu-$name-loadgen.txt"; } | tee -a "$OUT/threadcpu-$name.txt"
  stop_server
}

# stereocost NAME SCENE EWxEH HZ [SERVER ARGS] (issue 94): what a headset's frame costs the GPU
# against a mono frame of one eye. One session alone on the server each way (nothing else on the
# GPU), 10 s on the bicycle path at HZ poses a second, the head turning as catgs-loadgen --stereo
# turns it: the left eye's view alone (--mono-eye: EWxEH, the eye's vertical field of view), then
# the headset (--stereo EWxEH@HZ: both eyes). Per row the renderer's frame time and
# stages (FrameTimings means; the GPU's own events), the encode and the pose-to-frame p95 ->
# $OUT/stereocost-NAME.txt, JSON in $W/json/stereocost-NAME-{mono,stereo}.json.
stereocost() {
  local name=$1 scene=$2 eye=$3 hz=$4 W=/tmp/catgs_sweep
  shift 4
  export LD_LIBRARY_PATH=$SRV/lib
  start_server "$(scene_file "$scene")" "$W/server_stereocost-$name.log" --pipeline exact "$@" || return 1
  local trace="$W/${scene}_mipnerf360_bicycle.trace"
  "$SRV/bin/catgs-loadgen" --port "$PORT" --sessions 1 --stereo "$eye@$hz" --mono-eye --trace "$trace" --seconds 10 \
    --warmup 30 --progress 0 --json "$W/json/stereocost-$name-mono.json" > "$W/stereocost-$name-mono.txt" 2>&1
  "$SRV/bin/catgs-loadgen" --port "$PORT" --sessions 1 --stereo "$eye@$hz" --trace "$trace" --seconds 10 \
    --warmup 30 --progress 0 --json "$W/json/stereocost-$name-stereo.json" > "$W/stereocost-$name-stereo.txt" 2>&1
  stop_server
  python3 - "$W/json/stereocost-$name-mono.json" "$W/json/stereocost-$name-stereo.json" "$name" <<'PY' | tee "$OUT/stereocost-$name.txt"
import json, sys
rows = []
for label, path in (('mono, one eye', sys.argv[1]), ('stereo, both eyes', sys.argv[2])):
    t = json.load(open(path))['run']['total']; s = t['server']; st = s['render_stages_ms']
    rows.append((label, st['frame'], st['preprocess'], st['keys'], st['sort'], st['ranges'], st['rasterize'],
                 s['splats_mean'], s['encode_ms'], t['latency']['p95_ms'], t['fps_min']))
print('%s: the renderer\'s frame on the GPU (ms, means), one session alone' % sys.argv[3])
print('%-18s %7s %7s %6s %6s %6s %7s %10s %7s %7s %6s' % ('row', 'frame', 'preproc', 'keys', 'sort', 'ranges', 'raster',
                                                     'splats', 'encode', 'p95', 'FPS'))
for r in rows:
    print('%-18s %7.2f %7.2f %6.2f %6.2f %6.2f %7.2f %10.0f %7.2f %7.1f %6.1f' % r)
print('stereo / mono frame: %.2fx' % (rows[1][1] / rows[0][1]))
PY
}

# depth_share DIR: the depth grids' bytes (Frame.depth_grid's codes) against the access units' in
# a --record folder's sessions.
depth_share() {
  python3 - "$1" <<'PY'
import glob, sys, zlib
au = depth = deflated = frames = grids = 0
for f in glob.glob(sys.argv[1] + '/*/frames.tsv'):
    for line in open(f):
        if line.startswith('#'): continue
        col = line.rstrip('\n').split('\t')
        frames += 1; au += int(col[8])
        if col[10] != '-':
            grids += 1
            sent = bytes.fromhex(col[10].split(',')[4])  # deflated (proto/depth_grid_coding.h)
            depth += len(zlib.decompress(sent)); deflated += len(sent)
print('depth grids: %d of %d frames, %d bytes sent against %d of video: %.1f%% of the stream (raw codes %d, %.1f%%)' % (
    grids, frames, deflated, au, 100.0 * deflated / max(1, deflated + au), depth, 100.0 * depth / max(1, depth + au)))
PY
}

# clientcpu NAME SCENE N: catgs-loadgen's own CPU time (issue 92) for N sessions of 10 s at 720p
# on SCENE's three real paths: fitted by the client (`real:`, --scene: the fit that made the client
# cost more than the server on the big cities) by the landed binary (catgs-loadgen-landed), then
# by this one, then this one replaying the paths fitted beforehand (`scenes`' .trace files: what
# the client costs while streaming), one after another against one server ->
# $OUT/clientcpu-NAME.txt.
clientcpu() {
  local name=$1 scene=$2 n=$3 W=/tmp/catgs_sweep T=$ROOT/.carry_srv/traces
  export LD_LIBRARY_PATH=$SRV/lib
  start_server "$(scene_file "$scene")" "$W/server_clientcpu-$name.log" --cache-dir "$W/cache" || return 1
  local real="real:$T/mipnerf360_bicycle.cameras.json,real:$T/tandt_train.cameras.json,real:$T/flowers_sh3.cameras.json"
  local fitted="$W/${scene}_mipnerf360_bicycle.trace,$W/${scene}_tandt_train.trace,$W/${scene}_flowers_sh3.trace"
  local row
  for row in "catgs-loadgen-landed --scene $(scene_file "$scene") --trace $real" \
    "catgs-loadgen --scene $(scene_file "$scene") --trace $real" "catgs-loadgen --trace $fitted"; do
    # shellcheck disable=SC2086
    python3 - "$PORT" "$n" "$SRV/bin/"$row <<'PY' | tee -a "$OUT/clientcpu-$name.txt"
import resource, subprocess, sys, time
port, n, cmd = sys.argv[1], sys.argv[2], sys.argv[3:]
t0 = time.time()
out = subprocess.run(cmd + ['--port', port, '--sessions', n, '--size', '1280x720', '--rate', '60', '--seconds', '10',
                            '--progress', '0'], capture_output=True, text=True).stdout
r = resource.getrusage(resource.RUSAGE_CHILDREN)
total = [l for l in out.splitlines() if l.startswith('total')]
own = [l for l in out.splitlines() if l.startswith('client CPU')]  # this build's own count, from the run's start
print('%s: %s sessions, client CPU %.1f s (user %.1f + sys %.1f) over %.1f s wall, the scene load included\n  %s%s' % (
    ' '.join(','.join(t.split('/')[-1] for t in c.split(',')) for c in cmd), n, r.ru_utime + r.ru_stime, r.ru_utime, r.ru_stime, time.time() - t0,
    total[0] if total else out[-400:], ('\n  ' + own[0]) if own else ''))
PY
  done
  stop_server
}

# readrate FILE: dd of FILE in 16 MiB pieces, page cache warm (as firstframe reads it) -> stdout.
readrate() {
  dd if="$1" of=/dev/null bs=16M 2>&1 | tail -1
}

# rd SCENE WxH SETTINGS [FRAMES]: catgs-encode-bench on SCENE's bicycle path (CUDA renders, x264)
# -> $OUT/rd_SCENE_WxH.json and its table.
rd() {
  local scene=$1 size=$2 settings=$3 frames=${4:-240} W=/tmp/catgs_sweep
  export LD_LIBRARY_PATH=$SRV/lib
  "$SRV/bin/catgs-encode-bench" --scene "$W/$scene.compressed.ply" --trace "$W/${scene}_mipnerf360_bicycle.trace" \
    --renderer cuda --width "${size%x*}" --height "${size#*x}" --frames "$frames" --settings "$settings" \
    --json "$OUT/rd_${scene}_$size.json"
}

# captures: the real captures beside the city for catgs-encode-bench (issue 51): tumblewood_sh2
# alone (scale 1), biker and guitar (.carry_srv/scenes, or the bundled biker) with the bicycle
# path fitted to each, flowers_sh3 (.carry_srv/scenes/flowers_sh3.ply.xz) on its own cameras.
captures() {
  local W=/tmp/catgs_sweep S=$ROOT/.carry_srv
  export LD_LIBRARY_PATH=$SRV/lib
  [ -f "$W/flowers_sh3.ply" ] || xz -dc "$S/scenes/flowers_sh3.ply.xz" > "$W/flowers_sh3.ply" || return 1
  [ -f "$W/biker.compressed.ply" ] || cp -f "$ROOT/assets/scenes/biker.compressed.ply" "$W/" || return 1
  [ -f "$W/guitar.compressed.ply" ] || cp -f "$S/scenes/guitar.compressed.ply" "$W/" || return 1
  cp -f "$W/tumblewood_sh2.compressed.ply" "$W/tumblewood_sh2_1.compressed.ply" 2>/dev/null
  for scene in tumblewood_sh2_1 biker guitar; do
    [ -f "$W/${scene}_mipnerf360_bicycle.trace" ] && continue
    "$SRV/bin/catgs-scene" trace --scene "$W/$scene.compressed.ply" --cameras "$S/traces/mipnerf360_bicycle.cameras.json" \
      --out "$W/${scene}_mipnerf360_bicycle.trace" --scale 1 --frames 1200 || return 1
  done
}

# rdtrace SCENE_FILE TRACE WxH SETTINGS FRAMES TAG: catgs-encode-bench of any scene and trace
# (cameras:C.json for a capture's own) -> $OUT/rd_TAG.json and its table.
rdtrace() {
  local file=$1 trace=$2 size=$3 settings=$4 frames=$5 tag=$6
  export LD_LIBRARY_PATH=$SRV/lib
  "$SRV/bin/catgs-encode-bench" --scene "$file" --trace "$trace" --renderer cuda --width "${size%x*}" \
    --height "${size#*x}" --frames "$frames" --settings "$settings" --json "$OUT/rd_$tag.json"
}

# measure TAG N SIZE PORT TRACES SECONDS: one catgs-loadgen run of N sessions against the server
# (SERVER_PID) with the host's CPU, the server's CPU, GPU utilisation and the most device memory
# in use -> $W/json/TAG.json. CATGS_LOADGEN_ARGS: more catgs-loadgen options (e.g. --av1).
# thread_times: the clock (seconds), then a line per thread of the server: TID NAME TICKS (user +
# system clock ticks; a name may hold spaces: it is what stands between the parentheses).
thread_times() {
  date +%s.%N
  local t line
  for t in /proc/"$SERVER_PID"/task/*; do
    line=$(cat "$t/stat" 2>/dev/null) || continue
    local name=${line#*(}; name=${name%)*}
    local rest=${line##*) }
    read -r -a f <<< "$rest"
    echo "${t##*/} ${name// /_} $((f[11] + f[12]))"
  done
}

measure() {
  local tag=$1 n=$2 size=$3 port=$4 traces=$5 seconds=$6 W=/tmp/catgs_sweep
  nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader,nounits -lms 200 > "$W/gpu_$tag.txt" &
  local smi=$! cpu0 srv0 cpu1 srv1
  cpu0=$(head -1 /proc/stat)
  srv0=$(awk '{print $14 + $15}' "/proc/$SERVER_PID/stat")
  thread_times > "$W/threads0_$tag.txt"
  local rc=0
  "$SRV/bin/catgs-loadgen" --port "$port" --sessions "$n" --size "$size" --trace "$traces" \
    --rate 60 --seconds "$seconds" --warmup 30 --json "$W/json/$tag.json" ${CATGS_LOADGEN_ARGS:-} > "$W/load_$tag.txt" 2>&1 || rc=1
  cpu1=$(head -1 /proc/stat)
  srv1=$(awk '{print $14 + $15}' "/proc/$SERVER_PID/stat")
  thread_times > "$W/threads1_$tag.txt"
  kill "$smi" 2>/dev/null; wait "$smi" 2>/dev/null
  python3 - "$W/json/$tag.json" "$cpu0" "$cpu1" "$srv0" "$srv1" "$W/gpu_$tag.txt" "$W/threads0_$tag.txt" \
    "$W/threads1_$tag.txt" <<'PY'
import json, os, re, sys
path, c0, c1, s0, s1, gpu, t0, t1 = sys.argv[1:]
a = [int(x) for x in c0.split()[1:]]; b = [int(x) for x in c1.split()[1:]]
d = [y - x for x, y in zip(a, b)]
busy = 1 - (d[3] + d[4]) / max(1, sum(d))          # idle + iowait
rows = [[float(v) for v in line.split(",")] for line in open(gpu) if line.count(",") == 1]
u = [r[0] for r in rows]; mem = [r[1] for r in rows]   # percent; MiB of device memory in use
j = json.load(open(path))
j["host"] = {"cpu_busy_fraction": busy, "server_cpu_seconds": (int(s1) - int(s0)) / os.sysconf("SC_CLK_TCK"),
             "gpu_util_mean": sum(u) / len(u) if u else None, "gpu_util_samples": len(u),
             "gpu_memory_used_mib_max": max(mem) if mem else None}
# The server's threads (thread_times: the clock, then TID NAME TICKS lines): each one's share of
# a core over the step, the busiest first, and per name family (digits dropped: catgs-lane,
# catgs-pool, catgs-lws, catgs-x264: x264's sliced threads).
def times(f):
    lines = open(f).read().split("\n")
    return float(lines[0]), {l.split(" ", 1)[0]: l.split(" ", 1)[1].rsplit(" ", 1) for l in lines[1:] if l}
w0, a = times(t0); w1, b = times(t1)
hz, wall = os.sysconf("SC_CLK_TCK"), max(1e-3, w1 - w0)
# A thread absent from the first snapshot started during the step (x264's sliced threads of the
# step's new sessions): every tick of it is the step's.
share = sorted(((name, (int(ticks) - int(a.get(tid, [name, 0])[1])) / hz / wall) for tid, (name, ticks) in b.items()),
               key=lambda x: -x[1])
families = {}
for name, f in share:
    fam = families.setdefault(name if name == "catgs-x264" else re.sub(r"\d+$", "", name),
                              {"threads": 0, "cores": 0.0, "busiest": 0.0})
    fam["threads"] += 1; fam["cores"] += f; fam["busiest"] = max(fam["busiest"], f)
j["host"]["server_threads_busiest"] = [[n, round(f, 3)] for n, f in share[:8]]
j["host"]["server_thread_families"] = families
json.dump(j, open(path, "w"), indent=1)
PY
  return $rc
}

# ramp NAME SCENE WxH PIPELINE START STEP MAX P95_MS MIN_FPS [SERVER ARGS...]: sessions START,
# START + STEP, ... until the pooled p95 pose-to-frame passes P95_MS or the slowest session's FPS
# falls under MIN_FPS (or a session fails); each count a catgs-loadgen run of 6 s (30 frames of
# warm-up) on the three real paths in turn -> $W/json/ramp-NAME_N.json; the table is ramp_table.py.
ramp() {
  local name=$1 scene=$2 size=$3 pipeline=$4 start=$5 step=$6 max=$7 p95=$8 fps=$9 W=/tmp/catgs_sweep
  shift 9
  export LD_LIBRARY_PATH=$SRV/lib
  start_server "$(scene_file "$scene")" "$W/server_ramp-$name.log" --pipeline "$pipeline" "$@" || return 1
  local traces="$W/${scene}_mipnerf360_bicycle.trace,$W/${scene}_tandt_train.trace,$W/${scene}_flowers_sh3.trace"
  echo "{\"name\": \"$name\", \"scene\": \"$scene\", \"size\": \"$size\", \"pipeline\": \"$pipeline\", \"args\": \"$*\", \"p95_bound\": $p95, \"fps_bound\": $fps}" > "$W/json/ramp-${name}.meta"
  for ((n = start; n <= max; n += step)); do
    measure "ramp-${name}_$n" "$n" "$size" "$PORT" "$traces" 6
    local verdict
    verdict=$(python3 -c "
import json,sys; j=json.load(open(sys.argv[1])); t=j['run']['total']
bad=[]
if t.get('errors',0): bad.append('%d errors' % t['errors'])
if t['latency']['p95_ms'] > $p95: bad.append('p95 %.1f ms' % t['latency']['p95_ms'])
if t['fps_min'] < $fps: bad.append('slowest %.1f FPS' % t['fps_min'])
print('; '.join(bad))" "$W/json/ramp-${name}_$n.json" 2>&1)
    echo "ramp $name: $n sessions: ${verdict:-held}"
    [ -n "$verdict" ] && break
  done
  grep -E "GPU|encoder:|ERROR" "$W/server_ramp-$name.log" | head -5
  stop_server
}

# hogramp NAME SCENE WxH HOG_GIB START STEP MAX [SERVER ARGS...] (issue 73): another process
# (catgs-memory-hog, tests/gpu/memory_hog.cu) holds HOG_GIB GiB of the GPU while sessions ramp
# START, START + STEP, ... MAX on the three real paths (6 s a step, as ramp). The ramp goes on past
# refusals at the door (they are what it shows) and stops where a session fails. Per step: sessions
# that streamed, were refused, failed; the slowest streamed session's FPS and the pooled p95; the
# server's memory counters (/metrics) -> $W/json/hogramp-NAME_N.json and stdout. HOG_GIB 0: no other
# process (a ramp that goes on past refusals: the splat budget's door, issue 72).
hogramp() {
  local name=$1 scene=$2 size=$3 hog=$4 start=$5 step=$6 max=$7 W=/tmp/catgs_sweep
  shift 7
  export LD_LIBRARY_PATH=$SRV/lib
  local hog_pid=""
  if [ "$hog" != 0 ]; then
    "$SRV/bin/catgs-memory-hog" "$hog" > "$W/hog-$name.txt" 2>&1 &
    hog_pid=$!
    for _ in $(seq 1 240); do grep -q holding "$W/hog-$name.txt" && break; sleep 0.5; done
    echo "hog: $(cat "$W/hog-$name.txt")"
  fi
  start_server "$(scene_file "$scene")" "$W/server_hogramp-$name.log" --pipeline exact "$@" || {
    [ -n "$hog_pid" ] && kill "$hog_pid"
    return 1
  }
  grep -E "^gpu |renderer:" "$W/server_hogramp-$name.log"
  local traces="$W/${scene}_mipnerf360_bicycle.trace,$W/${scene}_tandt_train.trace,$W/${scene}_flowers_sh3.trace"
  for ((n = start; n <= max; n += step)); do
    measure "hogramp-${name}_$n" "$n" "$size" "$PORT" "$traces" 6
    local verdict
    verdict=$(python3 - "$W/json/hogramp-${name}_$n.json" "$PORT" "$n" "$hog" <<'PY'
import json, sys, urllib.request
path, port, n, hog = sys.argv[1:]
j = json.load(open(path)); t = j['run']['total']
text = urllib.request.urlopen('http://127.0.0.1:%s/metrics' % port).read().decode()
m = {l.split(' ')[0]: float(l.split(' ')[1]) for l in text.split('\n') if l and not l.startswith('#') and ' ' in l}
keys = ['catgs_memory_refusals_total', 'catgs_memory_refusals_driver_total', 'catgs_render_out_of_memory_total',
        'catgs_render_memory_fallbacks_total', 'catgs_session_errors_total',
        'catgs_device_memory_driver_free_bytes{slot="0"}', 'catgs_device_memory_held_bytes{slot="0"}',
        'catgs_device_memory_session_bytes{slot="0"}', 'catgs_splat_budget_refusals_total',
        'catgs_lod_over_budget_frames_total']
j['server_metrics'] = {k: m.get(k) for k in keys}
j['hog_gib'] = float(hog)
json.dump(j, open(path, 'w'), indent=1)
streamed = t['sessions'] - t['refused'] - t['failed']
bounds = [s['server']['lod_error_px_mean'] for s in j['run']['sessions'] if s.get('server') and s['server'].get('lod_error_px_mean', 0) > 0] or [0]
print('%s sessions asked: %d streamed, %d refused, %d failed; slowest %.1f FPS, p95 %.1f ms; server: %d refused at the door '
      '(%d by the driver), %d frames drawn after a failed growth, %d dropped; driver free %.1f GiB; splat budget: %d refused, '
      '%d frames over it at the ceiling; LOD bound px mean %.2f, max of session means %.2f' % (
      n, streamed, t['refused'], t['failed'], t['fps_min'], t['latency']['p95_ms'],
      m.get('catgs_memory_refusals_total', 0), m.get('catgs_memory_refusals_driver_total', 0),
      m.get('catgs_render_memory_fallbacks_total', 0), m.get('catgs_render_out_of_memory_total', 0),
      m.get('catgs_device_memory_driver_free_bytes{slot="0"}', 0) / 2**30,
      m.get('catgs_splat_budget_refusals_total', 0), m.get('catgs_lod_over_budget_frames_total', 0),
      sum(bounds) / len(bounds), max(bounds)))
PY
    )
    echo "hogramp $name: $verdict"
    python3 -c "import json,sys; sys.exit(1 if json.load(open(sys.argv[1]))['run']['total']['failed'] else 0)" \
      "$W/json/hogramp-${name}_$n.json" || break
  done
  grep -E "ERROR|out of device memory" "$W/server_hogramp-$name.log" | head -5
  stop_server
  [ -n "$hog_pid" ] && kill "$hog_pid" 2>/dev/null && wait "$hog_pid" 2>/dev/null
}

case "${1:-}" in
  prepare) shift; prepare "$@" ;;
  check) OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; check ;;
  sweep) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; sweep "$@" ;;
  unpack) unpack ;;
  scenes) scenes ;;
  bigcity) shift; bigcity "$@" ;;
  firstframe) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; firstframe "$@" ;;
  rd) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; rd "$@" ;;
  captures) captures ;;
  rdtrace) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; rdtrace "$@" ;;
  pictures) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; pictures "$@" ;;
  ramp) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; ramp "$@" ;;
  hogramp) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; hogramp "$@" ;;
  compactcity) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; compactcity "$@" ;;
  compactcopy) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; compactcopy "$@" ;;
  readrate) shift; readrate "$@" ;;
  shown) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; shown "$@" ;;
  clientcpu) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; clientcpu "$@" ;;
  threadcpu) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; threadcpu "$@" ;;
  stereocost) shift; OUT=${OUT:-$ROOT/out/gpu_server}; mkdir -p "$OUT"; stereocost "$@" ;;
  *) echo "usage: $0 prepare [BUILD_DIR] | check | sweep [--seconds S] [--counts \"1 2 4\"] [--sizes \"WxH ...\"]" >&2; exit 2 ;;
esac
