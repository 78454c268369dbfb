#!/usr/bin/env bash
# Installs the Debian/Ubuntu packages the build, the server, the tests and the container test need
# (idempotent). Uses sudo when not root. CUDA is not installed here: the CUDA core builds only
# where /usr/local/cuda/bin/nvcc already exists (see README "GPU").
# usage: install_deps.sh [GROUP...]   groups: build (compile the server: what the Docker images'
# build stages install), test (GoogleTest, clang-format, node/npm, chromium, clang + libFuzzer), containers (podman,
# buildah, runc, debootstrap: the container test, tests/container). Default: all three.
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
build=(
  build-essential cmake ninja-build pkg-config
  libboost-dev libwebsockets-dev libssl-dev
  libavcodec-dev libavformat-dev libavutil-dev libswscale-dev libx264-dev
  libprotobuf-dev protobuf-compiler
  libglm-dev nlohmann-json3-dev libstb-dev libcli11-dev
  zlib1g-dev libzstd-dev libtinygltf-dev libwebp-dev libzip-dev libxxhash-dev
)
test=(git clang-format libgtest-dev nodejs npm chromium clang libclang-rt-dev)
containers=(podman buildah runc debootstrap uidmap fuse-overlayfs slirp4netns)
groups=("$@")
[ "${#groups[@]}" -gt 0 ] || groups=(build test containers)
packages=()
for g in "${groups[@]}"; do
  case "$g" in
    build) packages+=("${build[@]}") ;;
    test) packages+=("${test[@]}") ;;
    containers) packages+=("${containers[@]}") ;;
    *) echo "install_deps.sh: unknown group '$g' (build, test, containers)" >&2; exit 2 ;;
  esac
done
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# Debian's npm conflicts with NodeSource's nodejs (which bundles npm): skip it when npm exists.
if command -v npm >/dev/null; then
  filtered=()
  for p in "${missing[@]+"${missing[@]}"}"; do [ "$p" = npm ] || [ "$p" = nodejs ] || filtered+=("$p"); done
  missing=("${filtered[@]+"${filtered[@]}"}")
fi
if [ "${#missing[@]}" -gt 0 ]; then
  echo "install_deps.sh: installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "install_deps.sh: all packages present (${groups[*]})"
fi
