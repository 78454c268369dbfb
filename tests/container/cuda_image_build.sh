#!/usr/bin/env bash
# Builds docker/Dockerfile.cuda where NVIDIA's registry cannot be reached (this project's build
# machines: no registry, Ubuntu's and Debian's archives only), and checks the image without a GPU.
# Not part of the test suite: the build compiles the CUDA core for five GPU architectures, which
# takes tens of minutes on 2 cores (deploy/README.md "CUDA image" has the measured run).
#
# The Dockerfile starts FROM nvidia/cuda's devel and base images (Ubuntu 24.04). Stand-ins for
# both are made here and passed as the CUDA_DEVEL_IMAGE / CUDA_BASE_IMAGE build arguments:
#   base:  Ubuntu 24.04 (noble, minbase) by debootstrap from archive.ubuntu.com, its Release file
#          checked against the Ubuntu archive key (fingerprint pinned below), with nvidia/cuda's
#          NVIDIA_* and PATH environment. NVIDIA's base image adds the CUDA runtime library and
#          cuda-compat; catgs-server links the runtime statically and needs neither.
#   devel: base + this machine's CUDA toolkit (CUDA_HOME, default /usr/local/cuda): nvcc, its
#          compilers, headers (CUB among them) and the static runtime, at /usr/local/cuda.
# What differs from NVIDIA's images: the toolkit's files come from a runfile/pip install instead of
# NVIDIA's apt packages (same version), and the base has no libcudart.so (unused).
#
# Then: podman build of docker/Dockerfile.cuda with the stand-ins; checks: the binary carries SASS
# for every architecture the Dockerfile names (cuobjdump), it runs as uid 10001, `--help` works, and
# without a GPU `--renderer cuda` (the image's entrypoint) exits non-zero within seconds, saying the
# CUDA renderer is unavailable (a pod on a node without a usable GPU crash-loops instead of turning
# Ready on the CPU). --export DIR copies the binary, its runtime libraries and a catgs-loadgen out
# (DIR/image.tar.xz) for tests/container/cuda_image_gpu_run.sh on a GPU machine without containers.
# usage: cuda_image_build.sh [--jobs N] [--export DIR] [--skip-build]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
jobs=2
export_dir=""
skip_build=0
while [ $# -gt 0 ]; do
  case "$1" in
    --jobs) jobs="$2"; shift 2 ;;
    --export) export_dir="$2"; shift 2 ;;
    --skip-build) skip_build=1; shift ;;
    *) echo "usage: $0 [--jobs N] [--export DIR] [--skip-build]" >&2; exit 2 ;;
  esac
done
cuda_home="${CUDA_HOME:-/usr/local/cuda}"
cuda_home="$(readlink -f "$cuda_home")"
[ -x "$cuda_home/bin/nvcc" ] || { echo "cuda_image_build: no nvcc under $cuda_home (set CUDA_HOME)" >&2; exit 2; }
for tool in podman buildah debootstrap gpgv curl dpkg-deb; do
  command -v "$tool" >/dev/null || { echo "cuda_image_build: $tool is missing (install_deps.sh containers; gpgv, curl)" >&2; exit 2; }
done
cuda_version="$("$cuda_home/bin/nvcc" --version | sed -n 's/.*release \([0-9.]*\),.*/\1/p')"
base_image="localhost/catgs-cuda-standin:${cuda_version}-base-ubuntu24.04"
devel_image="localhost/catgs-cuda-standin:${cuda_version}-devel-ubuntu24.04"
image=localhost/catgs-stream:cuda-test
cache="${XDG_CACHE_HOME:-$HOME/.cache}/catgs"
mirror="${CATGS_UBUNTU_MIRROR:-http://archive.ubuntu.com/ubuntu}"
# "Ubuntu Archive Automatic Signing Key (2018) <ftpmaster@ubuntu.com>", which signs noble's Release.
ubuntu_key_fpr=F6ECB3762474EDA9D21B7022871920D1991BC93C
limits=(--ulimit nofile=20000:20000 --ulimit nproc=32768:32768)
mkdir -p "$cache"

ubuntu_keyring() {  # the archive keyring from ubuntu-keyring's .deb, its key's fingerprint checked
  local dir="$cache/ubuntu-keyring"
  local keyring="$dir/usr/share/keyrings/ubuntu-archive-keyring.gpg"
  if [ ! -s "$keyring" ]; then
    local deb
    deb="$(curl -fsS "$mirror/dists/noble/main/binary-amd64/Packages.gz" | gzip -dc |
      awk '/^Package: ubuntu-keyring$/ {p=1} p && /^Filename:/ {print $2; exit}')"
    curl -fsS -o "$cache/ubuntu-keyring.deb" "$mirror/$deb"
    rm -rf "$dir" && dpkg-deb -x "$cache/ubuntu-keyring.deb" "$dir"
  fi
  gpg --show-keys --with-colons "$keyring" 2>/dev/null | grep -q "^fpr:::::::::$ubuntu_key_fpr:" ||
    { echo "cuda_image_build: $keyring lacks the Ubuntu archive key $ubuntu_key_fpr" >&2; exit 1; }
  # The Release file debootstrap will trust must verify with it.
  curl -fsS -o "$cache/noble-InRelease" "$mirror/dists/noble/InRelease"
  gpgv --keyring "$keyring" "$cache/noble-InRelease" 2>&1 | grep -q "Good signature" ||
    { echo "cuda_image_build: noble's InRelease does not verify with the Ubuntu archive key" >&2; exit 1; }
  echo "$keyring"
}

make_base() {
  podman image exists "$base_image" && { echo "cuda_image_build: $base_image present"; return; }
  local tarball="$cache/ubuntu-noble-minbase.tar"
  if [ ! -s "$tarball" ]; then
    local keyring rootfs start
    keyring="$(ubuntu_keyring)"
    rootfs="$(mktemp -d "$cache/noble.XXXXXX")"
    start=$(date +%s)
    echo "cuda_image_build: debootstrap noble (minbase) from $mirror"
    # Debian 12's debootstrap has no "noble" script; Ubuntu releases since gutsy share one.
    debootstrap --variant=minbase --keyring="$keyring" noble "$rootfs" "$mirror" \
      /usr/share/debootstrap/scripts/gutsy >"$cache/debootstrap-noble.log" 2>&1 ||
      { tail -20 "$cache/debootstrap-noble.log" >&2; rm -rf "$rootfs"; exit 1; }
    printf 'deb %s noble main universe\ndeb %s noble-updates main universe\ndeb %s noble-security main universe\n' \
      "$mirror" "$mirror" "$mirror" >"$rootfs/etc/apt/sources.list"
    rm -rf "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/lib/apt/lists/*
    tar -C "$rootfs" -cf "$tarball.tmp" . && mv "$tarball.tmp" "$tarball"
    rm -rf "$rootfs"
    echo "cuda_image_build: debootstrap took $(( $(date +%s) - start )) s ($(du -h "$tarball" | cut -f1))"
  fi
  # nvidia/cuda's base image environment (the NVIDIA container runtime reads NVIDIA_*).
  podman import \
    --change 'ENV NVIDIA_VISIBLE_DEVICES=all' \
    --change 'ENV NVIDIA_DRIVER_CAPABILITIES=compute,utility' \
    --change "ENV CUDA_VERSION=$cuda_version" \
    --change 'ENV PATH=/usr/local/nvidia/bin:/usr/local/cuda/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'ENV LD_LIBRARY_PATH=/usr/local/nvidia/lib:/usr/local/nvidia/lib64' \
    --change 'CMD ["bash"]' "$tarball" "$base_image" >/dev/null
  echo "cuda_image_build: imported $base_image"
}

make_devel() {
  podman image exists "$devel_image" && { echo "cuda_image_build: $devel_image present"; return; }
  local c stage
  stage="$(mktemp -d "$cache/cuda.XXXXXX")"
  # The toolkit, not the libraries a CUDA install may carry beside it (cuDNN, NCCL, cuBLAS...).
  mkdir -p "$stage/lib"
  cp -a "$cuda_home/bin" "$cuda_home/include" "$cuda_home/nvvm" "$stage/"
  [ -d "$cuda_home/targets" ] && cp -a "$cuda_home/targets" "$stage/"
  cp -a "$cuda_home"/lib/*.a "$cuda_home"/lib/libcudart.so* "$cuda_home/lib/stubs" "$stage/lib/"
  [ -d "$cuda_home/lib/cmake" ] && cp -a "$cuda_home/lib/cmake" "$stage/lib/"
  ln -s lib "$stage/lib64"
  c="$(buildah from "$base_image")"
  buildah copy "$c" "$stage" "/usr/local/cuda-$cuda_version" >/dev/null
  buildah run --isolation chroot "$c" -- ln -s "cuda-$cuda_version" /usr/local/cuda
  buildah config --env LIBRARY_PATH=/usr/local/cuda/lib64/stubs "$c"
  buildah commit -q "$c" "$devel_image" >/dev/null
  buildah rm "$c" >/dev/null
  rm -rf "$stage"
  echo "cuda_image_build: committed $devel_image (CUDA $cuda_version from $cuda_home)"
}

make_base
make_devel
archs="$(sed -n 's/^ARG CUDA_ARCHITECTURES="\(.*\)"/\1/p' "$root/docker/Dockerfile.cuda")"
if [ "$skip_build" = 0 ]; then
  start=$(date +%s)
  echo "cuda_image_build: podman build docker/Dockerfile.cuda (JOBS=$jobs, architectures $archs)"
  podman build --runtime runc "${limits[@]}" --format docker -f "$root/docker/Dockerfile.cuda" \
    --build-arg "CUDA_DEVEL_IMAGE=$devel_image" --build-arg "CUDA_BASE_IMAGE=$base_image" \
    --build-arg "JOBS=$jobs" -t "$image" "$root" >"$cache/cuda-image-build.log" 2>&1 ||
    { tail -40 "$cache/cuda-image-build.log" >&2; exit 1; }
  echo "cuda_image_build: built $image in $(( $(date +%s) - start )) s; size $(podman image inspect "$image" --format '{{.Size}}' | awk '{printf "%.0f MB", $1/1e6}')"
fi

fail=0
check() { if eval "$2"; then echo "ok   $1"; else echo "FAIL $1"; fail=1; fi; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
ctr="$(podman create "$image")"
podman cp "$ctr:/usr/local/bin/catgs-server" "$tmp/catgs-server"
podman rm "$ctr" >/dev/null
# SASS per architecture the Dockerfile names (NN-real), and PTX for the plain one (90: JIT on newer).
# cuobjdump comes with a full toolkit; a pip/runfile subset may lack it (then on a GPU machine:
# `cuobjdump --list-elf catgs-server` on the exported binary).
if [ -x "$cuda_home/bin/cuobjdump" ]; then
  sass="$("$cuda_home/bin/cuobjdump" --list-elf "$tmp/catgs-server" | grep -o 'sm_[0-9]*' | sort -u | tr '\n' ' ')"
  ptx="$("$cuda_home/bin/cuobjdump" --list-ptx "$tmp/catgs-server" | grep -o 'sm_[0-9]*' | sort -u | tr '\n' ' ')"
  echo "cuda_image_build: SASS for: $sass; PTX for: $ptx"
  for a in $(tr ';' ' ' <<<"$archs"); do
    n="${a%-real}"
    check "SASS for sm_$n" "grep -q 'sm_$n ' <<<'$sass'"
    if [ "$a" = "$n" ]; then check "PTX for compute_$n" "grep -q 'sm_$n ' <<<'$ptx'"; fi
  done
else
  echo "cuda_image_build: no cuobjdump under $cuda_home/bin: the architectures were not listed"
fi
hc="$(podman image inspect "$image" --format '{{json .Config.Healthcheck}}' 2>/dev/null)"
check "HEALTHCHECK is catgs-server --probe" "grep -q '\"--probe\"' <<<'$hc'"
check "runs as uid 10001" "[ \"\$(podman run --rm --runtime runc ${limits[*]} --entrypoint id $image -u)\" = 10001 ]"
check "--help works" "podman run --rm --runtime runc ${limits[*]} --entrypoint catgs-server $image --help >/dev/null"
start=$(date +%s%N)
set +e
out="$(timeout 60 podman run --rm --runtime runc "${limits[@]}" "$image" 2>&1)"
rc=$?
set -e
ms=$(( ($(date +%s%N) - start) / 1000000 ))
echo "cuda_image_build: without a GPU the entrypoint exited $rc after $ms ms: $(grep -i 'cuda' <<<"$out" | tail -1)"
check "no GPU: exits non-zero (not the CPU fallback)" "[ $rc -ne 0 ] && [ $rc -ne 124 ]"
check "no GPU: says the CUDA renderer is unavailable" "grep -qi 'cuda renderer unavailable' <<<\"\$out\""
if [ -n "$export_dir" ]; then
  # The binary, the page, the libraries runtime_libs.sh put in the image (the binary's ldd closure
  # less the C library, which the GPU machine's own Ubuntu 24.04 provides), and a catgs-loadgen
  # built in the image's build stage (same compiler and libraries) to drive it there.
  mkdir -p "$export_dir/lib"
  out="$(readlink -f "$export_dir")"
  ctr="$(podman create "$image")"
  podman cp "$ctr:/usr/local/bin/catgs-server" "$export_dir/catgs-server"
  podman cp "$ctr:/opt/catgs/web_client" "$export_dir/web_client"
  podman rm "$ctr" >/dev/null
  # copy_closure BINARY: its ldd closure into /out/lib, dereferenced, less the C library.
  copy_closure='ldd "$0" | awk "/=> \// {print \$3}" | while read -r l; do
    case "$l" in */libc.so*|*/libm.so*|*/libpthread.so*|*/libdl.so*|*/librt.so*|*/ld-linux*) ;;
    *) [ -e "/out/lib/${l##*/}" ] || cp -L "$l" /out/lib/ ;; esac; done'
  podman run --rm --runtime runc "${limits[@]}" --user 0 -v "$out:/out" --entrypoint sh "$image" \
    -c "$copy_closure" /usr/local/bin/catgs-server
  podman build --runtime runc "${limits[@]}" --format docker -f "$root/docker/Dockerfile.cuda" --target build \
    --build-arg "CUDA_DEVEL_IMAGE=$devel_image" --build-arg "CUDA_BASE_IMAGE=$base_image" \
    --build-arg "JOBS=$jobs" -t "$image-build" "$root" >>"$cache/cuda-image-build.log" 2>&1
  podman run --rm --runtime runc "${limits[@]}" -v "$out:/out" "$image-build" sh -c \
    "cmake --build build/cuda -j $jobs --target catgs-loadgen >/dev/null && cp build/cuda/bin/catgs-loadgen /out/"
  podman run --rm --runtime runc "${limits[@]}" -v "$out:/out" --entrypoint sh "$image-build" \
    -c "$copy_closure" /out/catgs-loadgen
  tar -C "$out" -cf - catgs-server catgs-loadgen lib web_client | xz -9 -T2 >"$out/image.tar.xz"
  echo "cuda_image_build: exported the binary, catgs-loadgen and $(ls "$export_dir/lib" | wc -l) libraries to $export_dir; $out/image.tar.xz is $(du -h "$out/image.tar.xz" | cut -f1) (tests/container/cuda_image_gpu_run.sh runs it on a GPU machine)"
fi
exit $fail
