#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz) with clang, AddressSanitizer and UBSan in build/fuzz,
# and runs each for SECONDS (default 60) from its seed corpus, printing libFuzzer's final line
# (executions, coverage). New inputs go to build/fuzz/corpus/<target> (kept between runs, not in
# the repository); a crash, leak or sanitizer report stops that target, leaves the reproducer in
# build/fuzz/crashes/ and makes the script exit 1 (add it to tests/fuzz/reproducers/<target>).
# Where clang or libFuzzer is missing it says so and exits 0 (install_deps.sh's test group has
# both).
# usage: scripts/run_fuzzers.sh [SECONDS]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
seconds=${1:-60}
fuzzer_lib=""
command -v clang++ >/dev/null && fuzzer_lib="$(clang++ -print-file-name=libclang_rt.fuzzer-x86_64.a)"
if [ -z "$fuzzer_lib" ] || [ ! -f "$fuzzer_lib" ]; then
  echo "run_fuzzers.sh: SKIP: clang++ with libFuzzer not found (apt-get install clang libclang-rt-dev)"
  exit 0
fi
build="$root/build/fuzz"
mkdir -p "$build/crashes"
echo "== fuzz build (clang, ASan + UBSan): $build"
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ \
  -DWITH_CUDA=OFF -DCATGS_FUZZ=ON > "$build/configure.log" 2>&1 || { tail -20 "$build/configure.log"; exit 1; }
cmake --build "$build" --target fuzz_scene fuzz_scene_cache fuzz_protocol fuzz_session > "$build/build.log" 2>&1 || { tail -40 "$build/build.log"; exit 1; }
status=0
for target in scene scene_cache protocol session; do
  corpus="$build/corpus/$target"
  mkdir -p "$corpus"
  dict=()
  words="$root/tests/fuzz/$target.dict"
  [ "$target" = session ] && words="$root/tests/fuzz/protocol.dict"  # a session's input is messages
  [ -f "$words" ] && dict=(-dict="$words")
  echo "== fuzz_$target for $seconds s"
  # -rss_limit_mb: a scene may legitimately take a few hundred MB; more is a finding.
  if (cd "$build/crashes" && "$build/bin/fuzz_$target" -max_total_time="$seconds" -rss_limit_mb=4096 -timeout=20 \
        -print_final_stats=1 "${dict[@]+"${dict[@]}"}" "$corpus" "$root/tests/fuzz/corpus/$target" \
        > "$build/fuzz_$target.log" 2>&1); then
    grep -E "^#[0-9]+.*(DONE|cov:)" "$build/fuzz_$target.log" | tail -1
    grep -E "^stat::number_of_executed_units|^stat::peak_rss_mb" "$build/fuzz_$target.log" || true
  else
    echo "fuzz_$target FOUND A PROBLEM (log: $build/fuzz_$target.log):"
    grep -E "ERROR|SUMMARY|Test unit written" "$build/fuzz_$target.log" | head -10
    status=1
  fi
done
exit $status
