#!/usr/bin/env bash
# Installs the Debian/Ubuntu packages the build, the server and the tests need (idempotent).
# Uses sudo when not root. CUDA is not installed here: the CUDA core builds only where
# /usr/local/cuda/bin/nvcc already exists (see README "GPU").
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
packages=(
  build-essential cmake ninja-build pkg-config git clang-format
  libboost-dev libwebsockets-dev
  libavcodec-dev libavutil-dev libswscale-dev libx264-dev
  libprotobuf-dev protobuf-compiler
  libglm-dev libgtest-dev nlohmann-json3-dev libstb-dev
  zlib1g-dev libzstd-dev
  nodejs npm chromium
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# Debian's npm conflicts with NodeSource's nodejs (which bundles npm): skip it when npm exists.
if command -v npm >/dev/null; then
  filtered=()
  for p in "${missing[@]}"; do [ "$p" = npm ] || [ "$p" = nodejs ] || filtered+=("$p"); done
  missing=("${filtered[@]+"${filtered[@]}"}")
fi
if [ "${#missing[@]}" -gt 0 ]; then
  echo "install_deps.sh: installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "install_deps.sh: all packages present"
fi
