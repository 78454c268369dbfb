#!/usr/bin/env bash
# How long the README's demo command takes on a fresh Debian 12 machine, as a newcomer meets it:
# a clean clone of HEAD into a debian:12 container (podman; the base from scripts/container_base.sh
# when no debian:12 image is there), `bash scripts/run_demo.sh --port PORT` run as root (the
# packages come from Debian's archive), then, from the host, the seconds until the page is served
# (GET / answers with the page) and until catgs-loadgen decodes a real session's frames.
# Prints one line per milestone (seconds from the container's start) and writes them as JSON.
# usage: scripts/demo_timing.sh --loadgen PATH/catgs-loadgen [--port N] [--cpus N] [--out FILE]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
loadgen="" port=18480 cpus=2 out=/tmp/demo_timing.json
while [ $# -gt 0 ]; do
  case "$1" in
    --loadgen) loadgen="$2"; shift 2 ;;
    --port) port="$2"; shift 2 ;;
    --cpus) cpus="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    *) echo "usage: $0 --loadgen PATH [--port N] [--cpus N] [--out FILE]" >&2; exit 2 ;;
  esac
done
[ -x "$loadgen" ] || { echo "demo_timing: --loadgen PATH/catgs-loadgen is required" >&2; exit 2; }
command -v podman >/dev/null || { echo "demo_timing: podman is missing (install_deps.sh containers)" >&2; exit 2; }
image=docker.io/library/debian:12
# container_base.sh imports the image under that name and prints what it did (to the log, not
# into $image).
podman image exists "$image" || bash "$root/scripts/container_base.sh" >&2
podman image exists "$image" || { echo "demo_timing: no $image after container_base.sh" >&2; exit 1; }

work="$(mktemp -d)"
name="catgs-demo-timing-$$"
cleanup() { podman rm -f "$name" >/dev/null 2>&1 || true; rm -rf "$work"; }
trap cleanup EXIT
git clone -q "$root" "$work/src"

start=$(date +%s.%N)
since() { echo "$(date +%s.%N) - $start" | bc; }
# --cpus: the 2-core machine the README promises the 5 minutes on.
podman --runtime runc run -d --name "$name" --network host --cpus "$cpus" \
  --ulimit nofile=20000:20000 --ulimit nproc=32768:32768 -v "$work/src:/src" "$image" \
  bash -c "cd /src && bash scripts/run_demo.sh --port $port" >/dev/null

page="" streamed=""
while [ -z "$streamed" ]; do
  if ! podman container exists "$name" || [ "$(podman inspect -f '{{.State.Running}}' "$name")" != true ]; then
    podman logs "$name" 2>&1 | tail -20
    echo "demo_timing: the demo exited before it streamed" >&2
    exit 1
  fi
  if [ -z "$page" ] && curl -fs "http://127.0.0.1:$port/" 2>/dev/null | grep -q "<html"; then
    page=$(since)
    echo "page served after ${page} s"
  fi
  if [ -n "$page" ] &&
    "$loadgen" --port "$port" --seconds 3 --size 640x360 --decode 1 --json "$work/loadgen.json" >/dev/null 2>&1 &&
    python3 -c "import json,sys; s=json.load(open(sys.argv[1]))['run']['sessions'][0]; sys.exit(0 if s['decoded'] > 10 else 1)" \
      "$work/loadgen.json" 2>/dev/null; then
    streamed=$(since)
    echo "a session streamed (decoded frames) after ${streamed} s"
  fi
  sleep 2
done
printf '{"cpus": %s, "page_s": %s, "streamed_s": %s, "commit": "%s"}\n' "$cpus" "$page" "$streamed" \
  "$(git -C "$root" rev-parse --short HEAD)" | tee "$out"
