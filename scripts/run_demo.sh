#!/usr/bin/env bash
# One command for a newcomer: install dependencies, build, and start the server on the bundled
# biker scene. Open the printed URL in a browser (Chrome/Edge/Firefox with WebCodecs).
# Extra arguments are passed to catgs-server (e.g. --port 9000 --scene other.ply).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/install_deps.sh"
bash "$root/scripts/setup_web.sh"
bash "$root/scripts/build.sh"
exec "$root/build/cpu/bin/catgs-server" --scene "$root/assets/scenes/biker.compressed.ply" \
  --web-root "$root/web_client" "$@"
