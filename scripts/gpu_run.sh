#!/usr/bin/env bash
# scripts/gpu_run.sh: the one entry point for the CUDA render core on a GPU machine.
#
# On the GPU machine (from the repository root, .carry/ carried):
#   scripts/gpu_run.sh [--prebuilt] [--quick] [--skip-large] [--filter REGEX] [--no-tests] [--no-bench]
#                      [--sanitize] [--frames N] [--compare LIST [--before DIR]]
#     1. builds the CUDA core, catgs-bench, catgs-gpu-tests and catgs-scene (build/gpu/bin, from the
#        carried GLM, nlohmann-json, stb and GoogleTest source), unless --prebuilt, which runs the
#        binaries in .carry/bin instead (built on the build machine by `prepare`; they need nothing
#        but the CUDA driver); a failed build falls back to those (when there) and exits non-zero;
#     2. runs the GPU tests (CUDA vs the CPU reference; GoogleTest cases, tests/gpu/*_test.cpp)
#        through ctest: `ctest --test-dir build/gpu -L gpu --output-on-failure`, each test a
#        process, their rows gathered into the table $OUT/gpu_tests.md (--quick: the quick subset,
#        label gpu_quick, at its small sizes; --skip-large: without the label gpu_large (8192 px,
#        2^31/2^32 entries, 49-copy city); --filter REGEX: ctest -R REGEX on the names
#        gpu.SUITE.NAME, e.g. 'gpu\.(Budget|Passes)\.' or 'gpu\.Lod\.'; --no-tests: none). With
#        --prebuilt (or a failed build) the binary runs them in one process instead (--filter then
#        picks among all its tests). --sanitize first runs the quick subset and the hostile values'
#        tests (issue 49; Hostile.*, 320x180) under compute-sanitizer memcheck, the binary directly
#        (--gtest_filter), -> $OUT/gpu_hostile_memcheck.md;
#     3. runs the benchmark (--no-bench: none) at 1920x1080, catgs-bench's 30 warm-up frames then
#        --frames N timed frames (default 600) at 120 FPS, sub-frame quality on every 3rd frame:
#        vanilla,exact,catgs,catgs-nocache,catgs-nosplit on tumblewood_sh2 (x10) and on the 13-copy
#        city built in memory, over each real camera path (mipnerf360_bicycle, tandt_train,
#        flowers_sh3: bench_{tumblewood,city}_PATH.json); the window table
#        exact,catgs-w2,catgs,catgs-w8,catgs-w16 (W = 2, 4, 8, 16) on the bicycle path
#        (bench_windows_{tumblewood,city}.json); and vanilla,exact,catgs on the city fly-over
#        (bench_city_flyover.json + snapshots), all packed into $OUT/bench.tar.gz.
#     --compare LIST (after the tests, instead of the benchmark) runs the catgs-bench variants of
#     LIST (quoted, e.g. 'exact,catgs,catgs{motion_margin=0.2},catgs-w2{backoff=0}'; see
#     catgs-bench --help) side by side on tumblewood x10 and the city over the three real paths,
#     and on the city fly-over -> compare_{tumblewood,city}_PATH.json, compare_city_flyover.json,
#     packed into $OUT/compare.tar.gz.
#     --before DIR (with --compare) runs DIR/catgs-bench, an earlier build carried along (e.g.
#     .carry/bin_before, copied from .carry/bin before the next `prepare`), right after each of
#     those runs -> compare_before_*.json, in the same archive.
#     Everything printed goes to $OUT/gpu_run.log too. Exit status: non-zero if a test failed.
#
# On the build machine, once (fills .carry/, git-ignored):
#   scripts/gpu_run.sh prepare [BUILD_DIR]     (BUILD_DIR defaults to build/cuda)
#
# Carry list (.carry/, about 40 MiB; the device gets at most 64 MiB per run):
#   .carry/scenes/flowers_sh3.ply                   9.5 MB  (../shared/data/scenes)
#   .carry/scenes/biker.compressed.ply              2.5 MB
#   .carry/scenes/tumblewood_sh2.compressed.ply    21.8 MB  (catgs-scene compact: Morton order,
#                                                            SuperSplat compressed; the 85 MB
#                                                            original does not fit)
#   .carry/traces/*.cameras.json                    0.3 MB
#   .carry/deps/{include,share/cmake,lib}           ~8 MB   GLM, nlohmann-json, stb + libstb.a, zlib and
#                                                            zstd (static, for .spz), xxhash.h,
#                                                            a pkg-config shim for stb
#   .carry/deps/googletest.tar.xz                   0.2 MB  GoogleTest 1.12.1's source (Debian's
#                                                            /usr/src/googletest/googletest without
#                                                            its tests; tests/gpu builds it there)
#   .carry/bin/{catgs-bench,catgs-gpu-tests,catgs-scene}  prebuilt x86-64 (glibc 2.36), static
#                                                            cudart; bin/lib/: the libraries they link (libstb, libwebp, ...)
# Run with the device tool: command "scripts/gpu_run.sh", carry [".carry"].
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
CARRY=$ROOT/.carry

prepare() {
  local build=${1:-build/cuda}
  local data=${CATGS_DATA_DIR:-$ROOT/../shared/data}
  mkdir -p "$CARRY"/{scenes,traces,bin,deps/include,deps/lib/pkgconfig,deps/share/cmake,deps/bin}
  cp -f "$data/scenes/flowers_sh3.ply" "$data/scenes/biker.compressed.ply" "$CARRY/scenes/"
  cp -f "$data"/traces/*.cameras.json "$CARRY/traces/"
  # Copies from before the rotation-order fix (issue 18) lack the writer's "packRot order" comment.
  if ! head -c 4096 "$CARRY/scenes/tumblewood_sh2.compressed.ply" 2>/dev/null | grep -aq "packRot order"; then
    "$build/bin/catgs-scene" compact --scene "$data/scenes/tumblewood_sh2.ply" \
      --out "$CARRY/scenes/tumblewood_sh2.compressed.ply" --check-views 4 --up 0,-1,0 || return 1
  fi
  cp -rf /usr/include/glm /usr/include/nlohmann /usr/include/stb "$CARRY/deps/include/"
  cp -rf /usr/share/cmake/glm /usr/share/cmake/nlohmann_json "$CARRY/deps/share/cmake/"
  cp -f /usr/lib/x86_64-linux-gnu/libstb.a "$CARRY/deps/lib/"
  # .spz's codecs (render_core links them): static zlib and zstd with their headers.
  cp -f /usr/lib/x86_64-linux-gnu/libz.a /usr/lib/x86_64-linux-gnu/libzstd.a "$CARRY/deps/lib/"
  cp -f /usr/include/zlib.h /usr/include/zconf.h /usr/include/zstd.h /usr/include/zstd_errors.h "$CARRY/deps/include/"
  # glTF (.glb/.gltf) reader: tinygltf, header-only as render_core builds it.
  cp -f /usr/include/tiny_gltf.h "$CARRY/deps/include/"
  # The scene cache's checksums: xxHash, header-only as render_core builds it.
  cp -f /usr/include/xxhash.h "$CARRY/deps/include/"
  # GoogleTest for the GPU tests (tests/gpu/CMakeLists.txt builds it when find_package finds none).
  tar -C /usr/src/googletest -cJf "$CARRY/deps/googletest.tar.xz" googletest/CMakeLists.txt googletest/cmake \
    googletest/include googletest/src || return 1
  cat > "$CARRY/deps/lib/pkgconfig/stb.pc" <<'PC'
prefix=${pcfiledir}/../..
libdir=${prefix}/lib
includedir=${prefix}/include/stb
Name: stb
Description: single-file image libraries (static, carried)
Version: 0.0
Libs: -L${libdir} -lstb
Cflags: -I${includedir}
PC
  # The GPU machine may lack pkg-config: a shim that answers CMake's FindPkgConfig for stb.
  cat > "$CARRY/deps/bin/pkg-config" <<'SHIM'
#!/usr/bin/env bash
# Answers CMake's FindPkgConfig for the carried stb, zlib and libzstd (static, in ../lib).
d=$(cd "$(dirname "$0")/.." && pwd)
mods=() out=()
for a in "$@"; do case "$a" in --*) ;; *) mods+=("$a") ;; esac; done
# Modules it does not carry are absent, so optional ones (libwebp, libzip: SOG) are left out.
for m in "${mods[@]}"; do case "$m" in stb|zlib|libzstd) ;; *) exit 1 ;; esac; done
lib() { case "$1" in stb) echo -lstb ;; zlib) echo -lz ;; libzstd) echo -lzstd ;; esac; }
inc() { case "$1" in stb) echo "-I$d/include/stb" ;; *) echo "-I$d/include" ;; esac; }
for a in "$@"; do
  case "$a" in
    --version) echo 0.29.2; exit 0 ;;
    --modversion) echo 0.0; exit 0 ;;
    --exists|--print-errors|--short-errors) ;;
    --cflags|--cflags-only-I) for m in "${mods[@]}"; do out+=("$(inc "$m")"); done ;;
    --libs) out+=("-L$d/lib"); for m in "${mods[@]}"; do out+=("$(lib "$m")"); done ;;
    --libs-only-L) out+=("-L$d/lib") ;;
    --libs-only-l) for m in "${mods[@]}"; do out+=("$(lib "$m")"); done ;;
    --variable=prefix) echo "$d"; exit 0 ;;
    --variable=*) echo ""; exit 0 ;;
  esac
done
echo "${out[@]:-}"
SHIM
  chmod +x "$CARRY/deps/bin/pkg-config"
  cp -f "$build/bin/catgs-bench" "$build/bin/catgs-gpu-tests" "$CARRY/bin/"
  cp -f "$build/bin/catgs-scene" "$CARRY/bin/"
  mkdir -p "$CARRY/bin/lib"
  # The libraries the prebuilt tools link beyond glibc and the C++ runtime (libstb; libwebp,
  # libzip and their closure where this machine has them: the GPU image has none of them).
  ldd "$CARRY"/bin/catgs-* | awk '/=> \//{print $3}' | sort -u |
    grep -Ev '/(libc|libm|libdl|librt|libpthread|libresolv|libutil|libstdc\+\+|libgcc_s)\.so|/libcuda\.so' |
    while read -r lib; do cp -fL "$lib" "$CARRY/bin/lib/"; done
  strip "$CARRY"/bin/* 2>/dev/null || true
  du -sh "$CARRY"
}

if [ "${1:-}" = prepare ]; then
  shift
  prepare "$@"
  exit $?
fi

PREBUILT=0 QUICK=0 SKIP_LARGE=0 FILTER= TESTS=1 BENCH=1 SANITIZE=0 FRAMES=600 COMPARE= BEFORE=
while [ $# -gt 0 ]; do
  case "$1" in
    --prebuilt) PREBUILT=1 ;;
    --quick) QUICK=1 ;;
    --skip-large) SKIP_LARGE=1 ;;
    --filter) FILTER=$2; shift ;;
    --no-tests) TESTS=0 ;;
    --no-bench) BENCH=0 ;;
    --sanitize) SANITIZE=1 ;;
    --frames) FRAMES=$2; shift ;;
    --compare) COMPARE=$2; BENCH=0; shift ;;
    --before) BEFORE=$ROOT/$2; shift ;;
    *) echo "gpu_run.sh: unknown option $1" >&2; exit 2 ;;
  esac
  shift
done
OUT=${OUT:-$ROOT/out/gpu}
mkdir -p "$OUT"
exec > >(tee "$OUT/gpu_run.log") 2>&1
echo "== gpu_run.sh $(date -u +%FT%TZ)"
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm,clocks.max.sm --format=csv,noheader || true

if [ "$PREBUILT" = 1 ]; then
  BIN=$CARRY/bin
  export LD_LIBRARY_PATH=$BIN/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  BENCH_EXE=$BIN/catgs-bench TEST_EXE=$BIN/catgs-gpu-tests
else
  export PATH=/usr/local/cuda/bin:$PATH
  command -v pkg-config >/dev/null || export PATH=$PATH:$CARRY/deps/bin
  export PKG_CONFIG_PATH=$CARRY/deps/lib/pkgconfig
  t0=$(date +%s)
  mkdir -p "$ROOT/build"
  cmake -S "$ROOT" -B "$ROOT/build/gpu" -G Ninja -DCMAKE_BUILD_TYPE=Release -DWITH_CUDA=ON \
    -DCMAKE_CUDA_COMPILER=/usr/local/cuda/bin/nvcc -DCMAKE_CUDA_ARCHITECTURES=90 \
    -DCATGS_BUILD_SERVER=OFF -DCATGS_BUILD_TESTS=OFF -DCMAKE_PREFIX_PATH="$CARRY/deps" \
    > "$ROOT/build/gpu.log" 2>&1 &&
  ninja -C "$ROOT/build/gpu" catgs-bench catgs-gpu-tests catgs-scene >> "$ROOT/build/gpu.log" 2>&1
  rc=$?
  echo "== build: rc $rc in $(( $(date +%s) - t0 )) s"
  [ $rc -eq 0 ] || cp "$ROOT/build/gpu.log" "$OUT/build.log"
  BENCH_EXE=$ROOT/build/gpu/bin/catgs-bench TEST_EXE=$ROOT/build/gpu/bin/catgs-gpu-tests
  if [ $rc -ne 0 ]; then
    export LD_LIBRARY_PATH=$CARRY/bin/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
    tail -40 "$ROOT/build/gpu.log"
    [ -x "$CARRY/bin/catgs-gpu-tests" ] || exit $rc
    echo "== BUILD FAILED: falling back to the prebuilt binaries in .carry/bin"
    BENCH_EXE=$CARRY/bin/catgs-bench TEST_EXE=$CARRY/bin/catgs-gpu-tests
    build_failed=1
  fi
fi

S=$CARRY/scenes T=$CARRY/traces
mkdir -p "$ROOT/build"
status=${build_failed:-0}
# The GPU tests' environment (tests/gpu/gpu_test_support.h): the carried scenes and traces; a
# missing device or file fails a test rather than skipping it.
export CATGS_GPU_SCENES=$S CATGS_GPU_TRACES=$T CATGS_GPU_STRICT=1
unset CATGS_GPU_OUT CATGS_GPU_ROWS CATGS_GPU_QUICK
if [ "$SANITIZE" = 1 ]; then
  echo "== compute-sanitizer memcheck (quick subset)"
  CATGS_GPU_QUICK=1 compute-sanitizer --tool memcheck --error-exitcode 9 --print-limit 20 \
    "$TEST_EXE" --quick > "$ROOT/build/sanitizer.log" 2>&1
  rc=$?; echo "memcheck rc $rc"; tail -3 "$ROOT/build/sanitizer.log"
  [ $rc -eq 0 ] || { status=1; cp "$ROOT/build/sanitizer.log" "$OUT/"; }
  echo "== compute-sanitizer memcheck (hostile values, issue 49, 320x180)"
  CATGS_GPU_QUICK=1 CATGS_GPU_OUT="$OUT/gpu_hostile_memcheck.md" \
    compute-sanitizer --tool memcheck --error-exitcode 9 --print-limit 20 \
    "$TEST_EXE" --gtest_filter='Hostile.*' > "$ROOT/build/sanitizer_hostile.log" 2>&1
  rc=$?; echo "memcheck (hostile) rc $rc"; tail -3 "$ROOT/build/sanitizer_hostile.log"
  [ $rc -eq 0 ] || { status=1; cp "$ROOT/build/sanitizer_hostile.log" "$OUT/"; }
fi
if [ "$TESTS" = 1 ]; then
  echo "== GPU tests"
  t0=$(date +%s)
  rows=$ROOT/build/gpu_tests.rows  # every test process appends its rows; the table holds them all
  rm -f "$rows" "$OUT/gpu_tests.md"
  quick=(); [ "$QUICK" = 1 ] && quick=(CATGS_GPU_QUICK=1)
  if [ "$TEST_EXE" = "$ROOT/build/gpu/bin/catgs-gpu-tests" ]; then
    sel=(-L gpu); [ "$QUICK" = 1 ] && sel=(-L gpu_quick)
    [ "$SKIP_LARGE" = 1 ] && sel+=(-LE gpu_large)
    [ -n "$FILTER" ] && sel+=(-R "$FILTER")
    env "${quick[@]}" CATGS_GPU_OUT="$OUT/gpu_tests.md" CATGS_GPU_ROWS="$rows" \
      ctest --test-dir "$ROOT/build/gpu" "${sel[@]}" --output-on-failure
    rc=$?
  else  # prebuilt: the binary runs the tests in one process
    args=(); [ "$QUICK" = 1 ] && args+=(--quick); [ "$SKIP_LARGE" = 1 ] && args+=(--skip-large)
    if [ -n "$FILTER" ]; then
      names=$("$TEST_EXE" --gtest_list_tests | awk '/^[^ ]/ { s = $1 } /^  / { print "gpu." s $1 }' |
        grep -E -- "$FILTER" | sed 's/^gpu\.//' | paste -sd:)
      args=(--gtest_filter="${names:-NONE}")
    fi
    env "${quick[@]}" CATGS_GPU_OUT="$OUT/gpu_tests.md" "$TEST_EXE" "${args[@]}"
    rc=$?
  fi
  [ -f "$OUT/gpu_tests.md" ] && tail -1 "$OUT/gpu_tests.md"
  echo "== GPU tests: rc $rc in $(( $(date +%s) - t0 )) s"; [ $rc -eq 0 ] || status=1
fi
# real_paths PIPELINES PREFIX: PIPELINES side by side in one process per scene x path, on
# tumblewood_sh2 (x10) and the ~7 M city over each real camera path at 120 FPS, sub-frame
# quality on every 3rd frame -> PREFIX_{tumblewood,city}_PATH.json.
real_paths() {
  local path scene
  for path in mipnerf360_bicycle tandt_train flowers_sh3; do
    for scene in tumblewood city; do
      echo "== $(basename "$2"): $scene, real camera path $path at 120 FPS: $1"
      local size=(--scale 10); [ $scene = city ] && size=(--city)
      "$BENCH_EXE" --scene "$S/tumblewood_sh2.compressed.ply" "${size[@]}" --up 0,-1,0 \
        --trace "real:$T/$path.cameras.json" --width 1920 --height 1080 --pipeline "$1" \
        --frames "$FRAMES" --quality-every 3 --json "$2_${scene}_$path.json" || status=1
      [ -n "$BEFORE" ] || continue  # the earlier build, right after, on the same frames
      "$BEFORE/catgs-bench" --scene "$S/tumblewood_sh2.compressed.ply" "${size[@]}" --up 0,-1,0 \
        --trace "real:$T/$path.cameras.json" --width 1920 --height 1080 --pipeline "$1" \
        --frames "$FRAMES" --quality-every 3 --json "$2_before_${scene}_$path.json" || status=1
    done
  done
}
if [ "$BENCH" = 1 ]; then
  B=$ROOT/build/bench  # JSON and snapshots; packed into $OUT/bench.tar.gz (the device returns 8 files)
  rm -rf "$B"; mkdir -p "$B"
  # Issue 4's tables: every real camera path on tumblewood_sh2 (x10) and on the ~7 M city, all
  # pipelines and ablations side by side in one process per scene x path; the window table
  # (W = 2, 4, 8, 16) on the bicycle path. Sub-frame quality on every 3rd frame.
  real_paths vanilla,exact,catgs,catgs-nocache,catgs-nosplit "$B/bench"
  echo "== bench: window sizes (W = 2, 4, 8, 16), bicycle path, tumblewood and city"
  "$BENCH_EXE" --scene "$S/tumblewood_sh2.compressed.ply" --scale 10 --up 0,-1,0 \
    --trace "real:$T/mipnerf360_bicycle.cameras.json" --width 1920 --height 1080 \
    --pipeline exact,catgs-w2,catgs,catgs-w8,catgs-w16 --frames "$FRAMES" --quality-every 3 \
    --json "$B/bench_windows_tumblewood.json" || status=1
  "$BENCH_EXE" --scene "$S/tumblewood_sh2.compressed.ply" --city --up 0,-1,0 \
    --trace "real:$T/mipnerf360_bicycle.cameras.json" --width 1920 --height 1080 \
    --pipeline exact,catgs-w2,catgs,catgs-w8,catgs-w16 --frames "$FRAMES" --quality-every 3 \
    --json "$B/bench_windows_city.json" || status=1
  echo "== bench: city fly-over (the public-renderer comparison; docs/DESIGN.md \"Measuring\")"
  "$BENCH_EXE" --scene "$S/tumblewood_sh2.compressed.ply" --city --up 0,-1,0 --trace flyover \
    --width 1920 --height 1080 --pipeline vanilla,exact,catgs --frames "$FRAMES" --quality-every 3 \
    --json "$B/bench_city_flyover.json" --snapshot-dir "$B" || status=1
fi
if [ -n "$COMPARE" ]; then
  real_paths "$COMPARE" "$OUT/compare"
  echo "== compare: city fly-over: $COMPARE"
  "$BENCH_EXE" --scene "$S/tumblewood_sh2.compressed.ply" --city --up 0,-1,0 --trace flyover \
    --width 1920 --height 1080 --pipeline "$COMPARE" --frames "$FRAMES" --quality-every 3 \
    --json "$OUT/compare_city_flyover.json" || status=1
  # The device returns 8 files: the JSONs go back packed (a run cut short returns them loose).
  (cd "$OUT" && tar czf compare.tar.gz compare_*.json && rm -f compare_*.json)
fi
[ "$BENCH" = 1 ] && tar czf "$OUT/bench.tar.gz" -C "$ROOT/build" bench
echo "== done: status $status"
exit $status
