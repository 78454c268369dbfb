#!/usr/bin/env bash
# Build and run the stage-3 sort microbenchmark: bash tests/gpu/sort_bench/run.sh [OUT_DIR]
# (default: $OUT, else the current directory). Writes OUT_DIR/sort_bench, OUT_DIR/sort_bench.json, OUT_DIR/sort_bench.md.
set -euo pipefail; OUT_DIR="$(mkdir -p "${1:-${OUT:-.}}" && cd "${1:-${OUT:-.}}" && pwd)"; NVCC="${NVCC:-$(command -v nvcc || echo /usr/local/cuda/bin/nvcc)}"; cd "$(dirname "$0")" && "$NVCC" -O3 -std=c++17 -arch=sm_90 -o "$OUT_DIR/sort_bench" sort_bench.cu && "$OUT_DIR/sort_bench" "$OUT_DIR/sort_bench.json" | tee "$OUT_DIR/sort_bench.md"
