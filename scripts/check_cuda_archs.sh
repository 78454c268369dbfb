#!/usr/bin/env bash
# Compiles every CUDA source of the render core for the oldest GPU architecture that
# docker/Dockerfile.cuda builds for (its CUDA_ARCHITECTURES list: sm_75, the T4), so that a kernel
# using a newer instruction (redux.sync's __reduce_*_sync needs sm_80, say) fails here instead of
# in the image's build. Device code only (-c); the CPU-only CI has nvcc but no GPU.
# Exit 77 (ctest SKIP) with the reason when nvcc is absent.
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
nvcc=${CUDACXX:-$(command -v nvcc || echo /usr/local/cuda/bin/nvcc)}
if [ ! -x "$nvcc" ]; then
  echo "SKIP: no nvcc (set CUDACXX or install the CUDA toolkit) to compile the CUDA image's architectures"
  exit 77
fi
archs=$(sed -n 's/^ARG CUDA_ARCHITECTURES="\(.*\)"/\1/p' "$root/docker/Dockerfile.cuda")
oldest=$(echo "$archs" | tr ';' '\n' | sed 's/-.*//' | sort -n | head -1)
[ -n "$oldest" ] || { echo "no CUDA_ARCHITECTURES in docker/Dockerfile.cuda"; exit 1; }
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
echo "compiling render_core/cuda/*.cu for sm_$oldest (Dockerfile.cuda: $archs)"
status=0
for f in "$root"/render_core/cuda/*.cu; do
  name=$(basename "$f")
  if ! "$nvcc" -I"$root/render_core/cuda" -I"$root/render_core" -O1 -std=c++17 --expt-relaxed-constexpr \
    -Xcudafe --diag_suppress=20012 --generate-code="arch=compute_$oldest,code=sm_$oldest" -x cu -c "$f" \
    -o "$out/$name.o" > "$out/$name.log" 2>&1; then
    echo "FAIL: $name does not compile for sm_$oldest:"
    grep -m 10 -i "error" "$out/$name.log"
    status=1
  else
    echo "ok: $name"
  fi
done
exit $status
