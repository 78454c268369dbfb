#!/usr/bin/env bash
# Makes the `debian:12` and `debian:12-slim` base images that docker/Dockerfile.cpu starts FROM,
# without a registry: debootstrap (minbase, bookworm) from Debian's archive, imported into podman.
# The root file system is cached as a tarball under ${XDG_CACHE_HOME:-~/.cache}/catgs (outside
# the repository) so later runs, and CI runs that keep the cache, skip debootstrap.
# Images already present in podman's store are kept. usage: bash scripts/container_base.sh
# Environment: CATGS_DEBIAN_MIRROR (default http://deb.debian.org/debian).
set -euo pipefail
mirror="${CATGS_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
cache="${XDG_CACHE_HOME:-$HOME/.cache}/catgs"
tarball="$cache/debian-bookworm-minbase.tar"

if podman image exists docker.io/library/debian:12 && podman image exists docker.io/library/debian:12-slim; then
  echo "container_base.sh: debian:12 and debian:12-slim present"
  exit 0
fi
if [ ! -s "$tarball" ]; then
  mkdir -p "$cache"
  rootfs="$(mktemp -d "$cache/rootfs.XXXXXX")"
  trap 'rm -rf "$rootfs"' EXIT
  echo "container_base.sh: debootstrap bookworm (minbase) from $mirror"
  start=$(date +%s)
  debootstrap --variant=minbase bookworm "$rootfs" "$mirror" >"$cache/debootstrap.log" 2>&1 ||
    { tail -20 "$cache/debootstrap.log" >&2; exit 1; }
  # What a registry's debian image has beside the packages: apt sources and no package cache.
  printf 'deb %s bookworm main\ndeb %s bookworm-updates main\ndeb http://deb.debian.org/debian-security bookworm-security main\n' \
    "$mirror" "$mirror" >"$rootfs/etc/apt/sources.list"
  rm -rf "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/lib/apt/lists/*
  tar -C "$rootfs" -cf "$tarball.tmp" . && mv "$tarball.tmp" "$tarball"
  echo "container_base.sh: debootstrap took $(( $(date +%s) - start )) s; cached $tarball ($(du -h "$tarball" | cut -f1))"
fi
# One root file system for both tags: minbase is already smaller than the registry's slim image.
podman import --change 'CMD ["bash"]' "$tarball" docker.io/library/debian:12 >/dev/null
podman tag docker.io/library/debian:12 docker.io/library/debian:12-slim
echo "container_base.sh: imported debian:12 and debian:12-slim from $tarball"
