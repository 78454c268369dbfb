#!/usr/bin/env bash
# One command for the tests: install dependencies, check the C++/CUDA format, build, run every
# test (unit, integration, browser end to end). Real data is read from CATGS_DATA_DIR (default ../shared/data beside the
# checkout); tests that need it skip with a visible reason when it is absent.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/install_deps.sh"
bash "$root/scripts/check_format.sh"
bash "$root/scripts/setup_web.sh"
bash "$root/scripts/build.sh"
ctest --preset cpu -j 2 "$@"
