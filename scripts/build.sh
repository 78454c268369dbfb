#!/usr/bin/env bash
# Configures and builds the CPU preset (build/cpu). Extra arguments go to cmake's configure step.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
cmake --preset cpu "$@" >/dev/null
cmake --build --preset cpu -j "$(nproc)"
