#!/bin/sh
# Copies the shared libraries BINARY needs (its ldd closure) under DEST, at their real directory
# (/lib -> /usr/lib resolved, so COPY onto a merged-/usr image never replaces its /lib link).
# The runtime stage then gets the libraries, not the packages: libavcodec's Debian package pulls in
# ~340 MB of dependencies and data (fonts, icons, X11) the server never touches.
# glibc and libstdc++ are left out: the runtime base image is the same distribution and has them.
# usage: runtime_libs.sh BINARY DEST
set -eu
bin="$1"
dest="$2"
if ldd "$bin" | grep "not found"; then
  echo "runtime_libs.sh: $bin has unresolved libraries" >&2
  exit 1
fi
ldd "$bin" | awk '$2 == "=>" && $3 ~ /^\// {print $3}' | while read -r lib; do
  name="$(basename "$lib")"
  case "$name" in
    libc.so.* | libm.so.* | libdl.so.* | libpthread.so.* | librt.so.* | ld-linux* | libgcc_s.so.* | libstdc++.so.*) continue ;;
  esac
  dir="$(readlink -f "$(dirname "$lib")")"
  mkdir -p "$dest$dir"
  cp -L "$lib" "$dest$dir/$name"
done
echo "runtime_libs.sh: $(find "$dest" -type f | wc -l) libraries, $(du -sh "$dest" | cut -f1)"
