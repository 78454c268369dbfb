#!/usr/bin/env bash
# One command for the tests: install dependencies, check the C++/CUDA format, build, run every
# test (unit, integration, browser end to end), then a minute of fuzzing per fuzz target. Real
# data is read from CATGS_DATA_DIR (default ../shared/data beside the checkout); tests that need
# it skip with a visible reason when it is absent.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/install_deps.sh"
bash "$root/scripts/check_format.sh"
bash "$root/scripts/setup_web.sh"
bash "$root/scripts/build.sh"
ctest --preset cpu -j 2 "$@"
# libFuzzer over the scene loaders and the protocol, a minute each (tests/fuzz/README.md).
bash "$root/scripts/run_fuzzers.sh" 60
