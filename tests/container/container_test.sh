#!/usr/bin/env bash
# The container test (ctest: container_cpu_image, label "container"): builds docker/Dockerfile.cpu
# with podman, runs it as a deployment would (non-root, read-only root, all capabilities dropped),
# and checks it from outside: /healthz, /readyz, the page, the image's HEALTHCHECK, a real session
# decoded by catgs-loadgen --decode 1, /readyz at the session limit, then SIGTERM during a session:
# /readyz 503, a new session refused with ERROR_SHUTTING_DOWN, frames during the drain, the session
# told ERROR_SHUTTING_DOWN at --drain-timeout-s, exit code 0.
# First (seconds, no base image needed) the build context: .dockerignore against a context with
# node_modules/, build/ and the like planted at the root and deeper, and the real context: what
# the Dockerfiles COPY or run is in it, no build tree or node_modules is.
# No registry is needed: scripts/container_base.sh makes the debian:12 base with debootstrap (cached
# under ~/.cache/catgs).
# OCI runtime: runc (runs here with the --ulimit values below); where runc is missing, crun, which
# the test tries (it fails on some hosts: setrlimit, hybrid cgroups). CATGS_CONTAINER_RUNTIME=NAME
# forces one. Exit 77 (ctest SKIP) only when podman is missing or no runtime can start a container
# here; the reason names what was found and what each runtime answered.
# usage: container_test.sh --loadgen PATH/catgs-loadgen [--jobs N] [--keep]
#        container_test.sh --context-only    (only the build context checks)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
loadgen=""
jobs=2
keep=0
context_only=0
while [ $# -gt 0 ]; do
  case "$1" in
    --loadgen) loadgen="$2"; shift 2 ;;
    --jobs) jobs="$2"; shift 2 ;;
    --keep) keep=1; shift ;;
    --context-only) context_only=1; shift ;;
    *) echo "usage: $0 --loadgen PATH [--jobs N] [--keep] | --context-only" >&2; exit 2 ;;
  esac
done
[ "$context_only" = 1 ] || [ -x "$loadgen" ] ||
  { echo "container_test: --loadgen PATH/catgs-loadgen is required" >&2; exit 2; }

skip() { echo "SKIP: $*"; exit 77; }
command -v podman >/dev/null ||
  skip "podman is not installed, so no image can be built or run (bash scripts/install_deps.sh containers: podman, runc)"
podman_version="$(podman --version 2>&1 | awk '{print $NF}')"
# The OCI runtime podman runs containers with. podman looks runtimes up in its own list of paths
# (containers.conf), not $PATH, so ask podman itself. Candidates: runc, then crun.
candidates=(runc crun)
[ -n "${CATGS_CONTAINER_RUNTIME:-}" ] && candidates=("$CATGS_CONTAINER_RUNTIME")
runtimes=()
why=""
for r in "${candidates[@]}"; do
  if out="$(podman --runtime "$r" info --format '{{.Host.OCIRuntime.Path}}' 2>&1)"; then
    runtimes+=("$r")
    echo "container_test: podman $podman_version, OCI runtime $r at $out"
  else
    why+="; $r: $(tail -1 <<<"$out")"
  fi
done
[ "${#runtimes[@]}" -gt 0 ] ||
  skip "podman $podman_version is installed but has no OCI runtime to start containers with (tried ${candidates[*]}${why}). Install runc (apt-get install runc, or bash scripts/install_deps.sh containers): runc runs this test here; crun fails on some hosts (setrlimit, hybrid cgroups)"

image=localhost/catgs-stream:cpu-test
name="catgs-ctest-$$"
limits=(--ulimit nofile=20000:20000 --ulimit nproc=32768:32768)
work="$(mktemp -d)"
failures=0
cleanup() {
  podman rm -f -t 0 "$name" >/dev/null 2>&1 || true
  [ "$keep" = 1 ] || rm -rf "$work"
}
trap cleanup EXIT
t_start=$(date +%s)
elapsed() { echo $(( $(date +%s) - t_start )); }
check() {  # check DESCRIPTION COMMAND...: runs the command, counts a failure
  local what="$1"; shift
  if "$@"; then echo "ok: $what"; else echo "FAIL: $what"; failures=$((failures + 1)); fi
}
json() { python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print(eval(sys.argv[2]))" "$@"; }

# 0. The build context, as podman sees it through .dockerignore: a FROM scratch image that copies
# the whole context (no base image, no container run), listed from `podman export`.
context_files() {  # context_files DIR: the files of DIR that reach a build, one path a line
  local tag="localhost/catgs-ctx-probe:$$" ctr
  printf 'FROM scratch\nCOPY . /ctx\n' >"$work/probe.Dockerfile"
  podman build -q -t "$tag" -f "$work/probe.Dockerfile" "$1" >"$work/probe-build.log" 2>&1 ||
    { cat "$work/probe-build.log" >&2; return 1; }
  ctr="$(podman create "$tag" /none)"
  podman export "$ctr" | tar -tf - | sed -n 's|^ctx/||p' | grep -v '/$' | sort
  podman rm "$ctr" >/dev/null
  podman rmi "$tag" >/dev/null
}
# Paths the Dockerfiles take from the context: COPY sources (not --from), what the runtime stage
# copies from the build stage's /src (the build tree aside), the scripts they run, and what
# `cmake --preset` reads.
needed_paths() {
  local f
  for f in "$root"/docker/Dockerfile.*; do
    grep -v '^[[:space:]]*#' "$f" | awk '
      $1 == "COPY" && $2 !~ /^--from/ { for (i = 2; i < NF; i++) if ($i !~ /^--/ && $i != ".") print $i }
      $1 == "COPY" && $2 ~ /^--from/ && $3 ~ /^\/src\// && $3 !~ /^\/src\/build\// { sub(/^\/src\//, "", $3); print $3 }'
    grep -v '^[[:space:]]*#' "$f" | grep -oE '(docker|scripts)/[A-Za-z0-9_.-]+\.sh' || true
  done
  printf '%s\n' CMakeLists.txt CMakePresets.json
}
# ignored_in LIST: the listed paths (from stdin) that have a component named node_modules, build,
# build-*, .git or __pycache__, or end in .swp.
ignored_in() { grep -E '(^|/)(node_modules|build|build-[^/]*|\.git|__pycache__)(/|$)|\.swp$' "$1" || true; }
mapfile -t needed < <(needed_paths | sort -u)
echo "container_test: the Dockerfiles need from the context: ${needed[*]}"
# Planted: what must stay out, at the root and deeper, and what must come through (the Dockerfiles'
# paths, and names that only look like build trees).
plant="$work/planted"
mkdir -p "$plant"
cp "$root/.dockerignore" "$plant/"
excluded=(node_modules/p tests/deploy/node_modules/p tests/e2e/node_modules/p web_client/node_modules/a/p
  build/cpu/CMakeCache.txt build-asan/p tests/unit/build/p render_core/build-x/p .git/HEAD
  tools/__pycache__/p.pyc server/x.cpp.swp out/p .carry/p)
kept=(scripts/build.sh server/build_info.h tests/CMakeLists.txt tools/output/p)
for p in "${excluded[@]}" "${kept[@]}"; do mkdir -p "$plant/$(dirname "$p")"; echo x >"$plant/$p"; done
for p in "${needed[@]}"; do mkdir -p "$plant/$p" && echo x >"$plant/$p/p"; done  # a folder or a file: both must pass
context_files "$plant" >"$work/planted.txt"
leaked=()
for p in "${excluded[@]}"; do grep -qxF "$p" "$work/planted.txt" && leaked+=("$p"); done
lost=()
for p in "${kept[@]}"; do grep -qxF "$p" "$work/planted.txt" || lost+=("$p"); done
for p in "${needed[@]}"; do grep -qxF "$p/p" "$work/planted.txt" || lost+=("$p"); done
check ".dockerignore keeps node_modules, build trees, .git out at any depth (planted: ${#excluded[@]})" \
  test "${#leaked[@]}" = 0
[ "${#leaked[@]}" = 0 ] || echo "  reached the build: ${leaked[*]}"
check ".dockerignore lets through what the Dockerfiles need (planted: $(( ${#kept[@]} + ${#needed[@]} )))" \
  test "${#lost[@]}" = 0
[ "${#lost[@]}" = 0 ] || echo "  left out: ${lost[*]}"
# The real context: everything the Dockerfiles name is there; no build tree or node_modules is.
context_files "$root" >"$work/context.txt"
missing=()
for p in "${needed[@]}"; do grep -qE "^$p(/|$)" "$work/context.txt" || missing+=("$p"); done
check "the build context has every path the Dockerfiles name" test "${#missing[@]}" = 0
[ "${#missing[@]}" = 0 ] || echo "  missing: ${missing[*]}"
check "the build context has no node_modules, build tree, .git or swap file" test -z "$(ignored_in "$work/context.txt")"
ignored_in "$work/context.txt" | head -5
echo "container_test: build context $(wc -l <"$work/context.txt") files, $(tar -C "$root" -cf - -T "$work/context.txt" | wc -c | awk '{printf "%.1f MB", $1 / 1e6}')"
if [ "$context_only" = 1 ]; then
  echo "container_test: context checks only, $failures failed"
  exit $(( failures > 0 ))
fi

# 1. The base image (debootstrap on the first run, then the cached tarball) and the image.
bash "$root/scripts/container_base.sh"
# podman may be installed where a runtime cannot start a container (an unprivileged CI sandbox,
# crun on a host with hybrid cgroups): the first runtime that runs one is used.
runtime=""
for r in "${runtimes[@]}"; do
  if podman --runtime "$r" run --rm "${limits[@]}" docker.io/library/debian:12 true >"$work/probe.log" 2>&1; then
    runtime="$r"
    break
  fi
  why+="; $r: $(tail -1 "$work/probe.log")"
done
[ -n "$runtime" ] ||
  skip "podman $podman_version cannot start a container here with any OCI runtime it has (podman --runtime R run --rm ${limits[*]} debian:12 true${why})"
echo "container_test: containers run with podman --runtime $runtime"
echo "container_test: base ready at $(elapsed) s; building $image (compile -j$jobs)"
t_build=$(date +%s)
# The build stage is tagged too, so that pruning the untagged layers of earlier runs (each source
# change leaves ~0.5 GB) keeps its apt layer cached for the next run.
for target in build runtime; do
  tag="$image"
  [ "$target" = build ] && tag="$image-build"
  args=(-t "$tag")
  [ "$target" = build ] && args+=(--target build)
  nice -n 10 podman --runtime "$runtime" build "${limits[@]}" --format docker --build-arg "JOBS=$jobs" \
    "${args[@]}" -f "$root/docker/Dockerfile.cpu" "$root" >>"$work/build.log" 2>&1 ||
    { tail -40 "$work/build.log"; echo "FAIL: image build ($target)"; exit 1; }
done
build_s=$(( $(date +%s) - t_build ))
podman image prune -f >/dev/null 2>&1 || true
size_mb=$(( $(podman image inspect --format '{{.Size}}' "$image") / 1000000 ))
echo "container_test: image built in $build_s s, $size_mb MB"
check "image runs as a non-root numeric user" \
  test "$(podman image inspect --format '{{.Config.User}}' "$image")" = "10001:10001"
check "image keeps its HEALTHCHECK" \
  grep -q -- "--probe" <<<"$(podman image inspect --format '{{json .Config.Healthcheck}}' "$image")"
check "no test tooling in the image" \
  podman --runtime "$runtime" run --rm "${limits[@]}" --entrypoint /bin/sh "$image" -c \
    '! command -v node && ! command -v npm && ! command -v chromium && ! command -v g++'

# 2. Run it as a Kubernetes pod would (deploy/k8s): read-only root, no capabilities.
port="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')"
drain_s=8
podman --runtime "$runtime" run -d --name "$name" "${limits[@]}" --read-only --cap-drop ALL \
  --security-opt no-new-privileges -p "127.0.0.1:$port:8080" "$image" \
  --scene /opt/catgs/assets/scenes/biker.compressed.ply --max-sessions 1 --threads 2 \
  --drain-timeout-s "$drain_s" >/dev/null
base="http://127.0.0.1:$port"
for _ in $(seq 1 300); do
  curl -fsS -o /dev/null "$base/readyz" 2>/dev/null && break
  sleep 0.2
done
check "/healthz 200 ok" test "$(curl -fsS "$base/healthz")" = "ok"
check "/readyz 200 ready" grep -q '^ready (0/1 sessions)' <<<"$(curl -fsS "$base/readyz")"
check "the page is served" grep -q '<canvas' <<<"$(curl -fsS "$base/")"
check "the page's protobuf schema is served" curl -fsS -o /dev/null "$base/viewer/catgs_stream.proto"
check "/metrics 200" grep -q '^catgs_sessions 0' <<<"$(curl -fsS "$base/metrics")"
check "HEALTHCHECK passes (podman healthcheck run)" podman healthcheck run "$name"
check "runs as uid 10001" test "$(podman exec "$name" id -u)" = "10001"

# 3. A real session through the container, every frame decoded.
"$loadgen" --port "$port" --sessions 1 --size 320x240 --rate 30 --seconds 4 --decode 1 \
  --json "$work/stream.json" >"$work/stream.txt" 2>&1 || true
frames=$(json "$work/stream.json" 'd["run"]["sessions"][0]["frames"]' 2>/dev/null || echo 0)
decoded=$(json "$work/stream.json" 'd["run"]["sessions"][0]["decoded"]' 2>/dev/null || echo -1)
echo "container_test: session streamed $frames frames, $decoded decoded"
check "a session streams frames" test "$frames" -ge 10
check "every frame decodes" test "$decoded" = "$frames"

# 4. Drain: SIGTERM while a session streams.
"$loadgen" --port "$port" --sessions 1 --size 320x240 --rate 30 --seconds 40 --decode 1 \
  --json "$work/drain.json" >"$work/drain.txt" 2>&1 &
live=$!
for _ in $(seq 1 100); do
  grep -q '^full' <<<"$(curl -sS "$base/readyz")" && break
  sleep 0.1
done
check "/readyz 503 full at --max-sessions" \
  test "$(curl -s -o /dev/null -w '%{http_code}' "$base/readyz")" = 503
sleep 1
metric() { curl -fsS "$base/metrics" | awk -v k="$1" '$1 == k {print $2}'; }
frames_at_term=$(metric catgs_frames_total)
t_term=$(date +%s.%N)
podman kill --signal TERM "$name" >/dev/null
sleep 0.5
check "/readyz 503 draining after SIGTERM" grep -q '^draining' <<<"$(curl -sS "$base/readyz")"
"$loadgen" --port "$port" --sessions 1 --size 320x240 --seconds 1 --json "$work/late.json" >"$work/late.txt" 2>&1 || true
check "a new session is refused with ERROR_SHUTTING_DOWN" \
  grep -q ERROR_SHUTTING_DOWN <<<"$(json "$work/late.json" 'd["run"]["sessions"][0]["refusal"]' 2>/dev/null)"
sleep 2
frames_mid=$(metric catgs_frames_total || echo 0)
echo "container_test: frames_total $frames_at_term at SIGTERM, $frames_mid 2.5 s into the drain"
check "the live session streams during the drain" test "${frames_mid:-0}" -gt "${frames_at_term:-0}"
code=$(podman wait "$name")
t_exit=$(date +%s.%N)
wait "$live" || true
drain_took=$(python3 -c "print(f'{$t_exit - $t_term:.1f}')")
echo "container_test: SIGTERM -> exit $code after $drain_took s (--drain-timeout-s $drain_s)"
check "exit code 0 after the drain" test "$code" = 0
check "the drain lasted the timeout, not longer" \
  python3 -c "import sys; sys.exit(0 if $drain_s - 0.5 <= $drain_took <= $drain_s + 6 else 1)"
check "the live session was told ERROR_SHUTTING_DOWN" \
  grep -q ERROR_SHUTTING_DOWN <<<"$(json "$work/drain.json" 'd["run"]["sessions"][0]["first_error"]' 2>/dev/null)"
check "the server logged the drain's end" grep -q 'drain ended (timeout)' <<<"$(podman logs "$name" 2>&1)"
echo "container_test: server: $(podman logs "$name" 2>&1 | grep 'drain ended')"

echo "container_test: image $size_mb MB, build $build_s s, total $(elapsed) s, $failures failed checks"
if [ "$failures" -gt 0 ]; then
  echo "--- container log"; podman logs "$name" 2>&1 | tail -30
  exit 1
fi
