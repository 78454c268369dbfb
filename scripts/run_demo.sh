#!/usr/bin/env bash
# One command for a newcomer: install the packages the server's build needs, build the server
# alone (build/demo: no tests, no tools) and start it on the bundled biker scene. Open the printed
# URL in a browser (Chrome/Edge/Firefox with WebCodecs). The tests, their packages, npm and every
# other target are scripts/run_tests.sh's (build/cpu).
# Extra arguments are passed to catgs-server (e.g. --port 9000 --scene other.ply).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/install_deps.sh" build
# The page loads the wire schema at run time (web_client/viewer/protocol.js): the .proto itself, which
# needs no npm (setup_web.sh also writes a JSON copy for static servers that refuse .proto).
cp "$root/proto/catgs_stream.proto" "$root/web_client/viewer/catgs_stream.proto"
cmake -S "$root" -B "$root/build/demo" -G Ninja -DCMAKE_BUILD_TYPE=Release -DWITH_CUDA=OFF \
  -DCATGS_BUILD_TESTS=OFF >/dev/null
cmake --build "$root/build/demo" --target catgs-server -j "$(nproc)"
exec "$root/build/demo/bin/catgs-server" --scene "$root/assets/scenes/biker.compressed.ply" \
  --web-root "$root/web_client" "$@"
