#!/usr/bin/env bash
# A visitor on a slow link (issue 50): the server on this host, catgs-loadgen in a network
# namespace of its own behind a veth pair whose host side is shaped with tc's token bucket
# filter (this kernel has no netem). One session at a time: unshaped first, then links at the
# fractions of the unshaped rate given; per link a row of FPS, pose-to-frame p50 / p95 / p99 /
# max after the first WARMUP seconds, and the received rate; then, with --check, the issue's
# bounds (exit 1 when one fails).
#
# usage: scripts/slow_link.sh BIN_DIR SCENE [--seconds 15] [--warmup 3] [--fractions 0.8,0.5,0.25]
#          [--check] [--p95-margin 300] [--max-ms 1000] [--min-fps 0.4] [--min-use 0.7] [--step]
#          [--beside N | --step | --ramp MAX | --busy S | --still] [--no-receipts] [--json OUT]
#          [-- SERVER_ARGS...]
#   The bounds (issue 50's by default): after WARMUP s, p95 <= unshaped p95 + P95_MARGIN ms, no
#   frame later than MAX_MS after its pose, FPS >= MIN_FPS x unshaped, received >= MIN_USE x the
#   link.
#   --beside N instead: N sessions from this host (not shaped) beside the namespace's session,
#   once with its link unshaped and once at the last fraction: the N sessions' pooled p95 and FPS
#   in both (a slow link must not slow the others).
#   --step instead: one 30 s session on a link that steps unshaped -> the last fraction ->
#   unshaped, 10 s each: p95 and max latency from 3 s after the step down to the step up, and
#   when the received rate (1 s windows) is back at 90% of the unshaped run's after the step up.
#   --ramp MAX instead: catgs-loadgen --ramp (+1 a step, up to MAX sessions, bound p95 <= unshaped
#   p95 + P95_MARGIN) in the namespace, all its sessions sharing one link shaped at the last
#   fraction of MAX unshaped streams (a household or a classroom behind one slow line).
#   --busy S instead (issue 64): one S-second session on the unshaped link from a client that
#   stalls 100-400 ms at random between reads (catgs-loadgen --read-stall-ms 100-400), as a busy
#   page does; the rows say whether the controller ever capped it (it must not) and how many cuts
#   /metrics counted.
#   --still instead (issue 64): the camera stops after the path (catgs-loadgen --still-s 4); per
#   link the PSNR of the picture shown 1 s and 3 s after the stop against the CPU reference render
#   of its pose, beside the same still view from a second server that runs the stream's crf with no
#   rate cap (--bitrate off --still-refine off), unshaped. The bound: within 1 dB of it after 1 s,
#   after 3 s on the last (slowest) fraction.
#   --late-receipts: its client sends receipts for frames it read late too (catgs-loadgen
#   --receipts 2), as clients did before issue 64.
#   --no-receipts: the namespace's client sends no frame receipts (catgs-loadgen --receipts 0), so
#   the server's rate controller reads the path from TCP_INFO alone, as for an older client.
#   SERVER_ARGS replace the default server settings after the scene (--renderer cpu --bitrate
#   2000 --crf 8: a 640x360 stream of about 400 kbit/s at the CPU's 12 frames/s).
# Needs root, ip netns and tc (iproute2); without them it prints SKIP and exits 77 (ctest's skip
# code). Traffic goes only to addresses inside the namespace it makes; everything it made is
# removed on exit.
set -uo pipefail
bin=$1 scene=$2
shift 2
seconds=15 warmup=3 fractions=0.8,0.5,0.25 check=0 json="" p95_margin=300 min_use=0.7 step=0 max_ms=1000 min_fps=0.4
beside=0 receipts=1 ramp=0 busy=0 still=0
server_args=(--renderer cpu --bitrate 2000 --crf 8)
while [ $# -gt 0 ]; do
  case "$1" in
    --seconds) seconds=$2; shift 2 ;;
    --warmup) warmup=$2; shift 2 ;;
    --fractions) fractions=$2; shift 2 ;;
    --check) check=1; shift ;;
    --no-receipts) receipts=0; shift ;;
    --late-receipts) receipts=2; shift ;;
    --ramp) ramp=$2; shift 2; [[ "$ramp" =~ ^[0-9]+$ ]] || { echo "slow_link.sh: --ramp needs a count" >&2; exit 2; } ;;
    --step) step=1; shift ;;
    --busy) busy=$2; shift 2; [[ "$busy" =~ ^[0-9]+$ ]] || { echo "slow_link.sh: --busy needs seconds" >&2; exit 2; } ;;
    --still) still=1; shift ;;
    --beside) beside=$2; shift 2 ;;
    --p95-margin) p95_margin=$2; shift 2 ;;
    --min-use) min_use=$2; shift 2 ;;
    --max-ms) max_ms=$2; shift 2 ;;
    --min-fps) min_fps=$2; shift 2 ;;
    --json) json=$2; shift 2 ;;
    --) shift; server_args=("$@"); break ;;
    *) echo "slow_link.sh: unknown argument $1" >&2; exit 2 ;;
  esac
done

skip() { echo "SKIP: $*"; exit 77; }
[ "$(id -u)" = 0 ] || skip "needs root for network namespaces (ip netns, tc)"
command -v ip >/dev/null && command -v tc >/dev/null || skip "iproute2 (ip, tc) not installed"
tag=$$
ns=catgs_sl_$tag host_if=vsl${tag}a ns_if=vsl${tag}b
net=10.234.$((tag % 250)).0
host_ip=${net%.0}.1 ns_ip=${net%.0}.2
port=$((18000 + tag % 2000))
work=$(mktemp -d)
server_pid="" crf_pid=""
cleanup() {
  [ -n "$server_pid" ] && kill "$server_pid" 2>/dev/null && wait "$server_pid" 2>/dev/null
  [ -n "$crf_pid" ] && kill "$crf_pid" 2>/dev/null && wait "$crf_pid" 2>/dev/null
  ip link del "$host_if" 2>/dev/null
  ip netns del "$ns" 2>/dev/null
  [ -n "${KEEP_WORK:-}" ] || rm -rf "$work"; [ -n "${KEEP_WORK:-}" ] && echo "work: $work"
}
trap cleanup EXIT
ip netns add "$ns" 2>/dev/null || skip "cannot make a network namespace here"
ip link add "$host_if" type veth peer name "$ns_if" || skip "cannot make a veth pair here"
ip link set "$ns_if" netns "$ns"
ip addr add "$host_ip/24" dev "$host_if" && ip link set "$host_if" up
ip netns exec "$ns" ip addr add "$ns_ip/24" dev "$ns_if"
ip netns exec "$ns" ip link set "$ns_if" up
ip netns exec "$ns" ip link set lo up

"$bin/catgs-server" --scene "$scene" --bind "$host_ip" --port "$port" "${server_args[@]}" > "$work/server.log" 2>&1 &
server_pid=$!
# GET PATH from the server (HTTP/1.0): the response, status line first.
get() {  # PATH [PORT]
  exec 3<>"/dev/tcp/$host_ip/${2:-$port}" || return 1
  printf 'GET %s HTTP/1.0\r\nHost: %s\r\n\r\n' "$1" "$host_ip" >&3
  timeout 2 cat <&3
  exec 3<&-
}
# Ready once /readyz answers 200: the port opens while the scene still loads, and a session
# then would be refused (SERVER_FULL, "the scene is loading").
ready() {
  local status
  status=$(get /readyz | head -1 | cut -d' ' -f2)
  [ "$status" = 200 ]
}
for _ in $(seq 150); do
  ready 2>/dev/null && break
  kill -0 "$server_pid" 2>/dev/null || { echo "slow_link.sh: the server exited:" >&2; cat "$work/server.log" >&2; exit 1; }
  sleep 0.2
done
ready 2>/dev/null || { echo "slow_link.sh: the server is not ready after 30 s" >&2; exit 1; }

# run NAME RATE_KBIT|none: one session, its loadgen JSON in $work/NAME.json.
run() {
  local name=$1 rate=$2
  tc qdisc del dev "$host_if" root 2>/dev/null
  [ "$rate" = none ] || tc qdisc add dev "$host_if" root tbf rate "${rate}kbit" burst 16kb latency 300ms
  ip netns exec "$ns" "$bin/catgs-loadgen" --host "$host_ip" --port "$port" --sessions 1 --size 640x360 \
    --trace orbit --rate 60 --decode 1 --seconds "$seconds" --warmup-s "$warmup" --receipts "$receipts" \
    --timeline --json "$work/$name.json" > "$work/$name.txt" 2>&1
}

if [ "$busy" -gt 0 ]; then
  # A busy client on the unshaped link: it reads every 100-400 ms.
  cuts_before=$(get /metrics | sed -n 's/^catgs_link_rate_decreases_total \([0-9]*\).*/\1/p')
  ip netns exec "$ns" "$bin/catgs-loadgen" --host "$host_ip" --port "$port" --sessions 1 --size 640x360 \
    --trace orbit --rate 60 --seconds "$busy" --warmup-s "$warmup" --read-stall-ms 100-400 --receipts "$receipts" --progress 0 \
    --json "$work/busy.json" > "$work/busy.txt" 2>&1
  cuts_after=$(get /metrics | sed -n 's/^catgs_link_rate_decreases_total \([0-9]*\).*/\1/p')
  python3 - "$work" "$busy" "$check" "$json" "${cuts_before:-0}" "${cuts_after:-missing}" <<'PY'
import json, sys
work, seconds, check, out, before, after = sys.argv[1], sys.argv[2], sys.argv[3] == "1", sys.argv[4], sys.argv[5], sys.argv[6]
s = json.load(open(f"{work}/busy.json"))["run"]["sessions"][0]
cuts = int(after) - int(before) if after.isdigit() else None
print(f"| busy client ({seconds} s, reads every 100-400 ms) | FPS | kbit/s received | link-limited Stats, lowest cap | link estimate kbit/s | cuts (/metrics) | errors |")
print("|---|---|---|---|---|---|---|")
print(f'| unshaped | {s["fps"]:.1f} | {s["bytes_per_second"] * 8 / 1000:.0f} | {s["link_limited_stats"]}, {s["link_cap_kbps_min"]} '
      f'| {s["link_kbps_last"]:.0f} | {cuts} | {s["errors"]} |')
if out:
    json.dump({"seconds": int(seconds), "fps": s["fps"], "limited_stats": s["link_limited_stats"],
               "cap_min_kbit": s["link_cap_kbps_min"], "cuts": cuts, "errors": s["errors"]}, open(out, "w"))
failed = []
if s["link_limited_stats"] or cuts != 0: failed.append(f'the controller capped a busy client on an unshaped link ({cuts} cuts)')
if s["errors"] or s["frames"] == 0: failed.append(f'{s["errors"]} errors, {s["frames"]} frames ({s["first_error"]})')
for f in failed: print("FAIL:", f)
sys.exit(1 if check and failed else 0)
PY
  exit $?
fi

if [ "$still" = 1 ]; then
  # The stream's crf with no rate cap, on a second server: the still picture to be within 1 dB of.
  "$bin/catgs-server" --scene "$scene" --bind "$host_ip" --port $((port + 1)) "${server_args[@]}" --bitrate off \
    --still-refine off > "$work/server_crf.log" 2>&1 &
  crf_pid=$!
  still_run() {  # NAME RATE_KBIT|none PORT
    tc qdisc del dev "$host_if" root 2>/dev/null
    [ "$2" = none ] || tc qdisc add dev "$host_if" root tbf rate "${2}kbit" burst 16kb latency 300ms
    ip netns exec "$ns" "$bin/catgs-loadgen" --host "$host_ip" --port "$3" --sessions 1 --size 640x360 \
      --trace orbit --rate 60 --seconds "$seconds" --still-s 4 --scene "$scene" --receipts "$receipts" \
      --progress 0 --json "$work/still_$1.json" > "$work/still_$1.txt" 2>&1
  }
  for _ in $(seq 300); do get /readyz $((port + 1)) 2>/dev/null | head -1 | grep -q " 200" && break; sleep 0.2; done
  still_run crf none $((port + 1))
  kill "$crf_pid" 2>/dev/null; wait "$crf_pid" 2>/dev/null
  run unshaped none
  unshaped_kbps=$(python3 -c "import json;print(round(json.load(open('$work/unshaped.json'))['run']['sessions'][0]['bytes_per_second']*8/1000))")
  names=(unshaped) rates=(none)
  still_run unshaped none "$port"
  for f in ${fractions//,/ }; do
    r=$(python3 -c "print(max(16, round($unshaped_kbps * $f)))")
    still_run "link_$f" "$r" "$port"
    names+=("link_$f") rates+=("$r")
  done
  tc qdisc del dev "$host_if" root 2>/dev/null
  python3 - "$work" "$check" "$json" "${names[*]}" "${rates[*]}" <<'PY'
import json, sys
work, check, out = sys.argv[1], sys.argv[2] == "1", sys.argv[3]
names, rates = sys.argv[4].split(), sys.argv[5].split()
def still(name):
    s = json.load(open(f"{work}/still_{name}.json"))["run"]["sessions"][0]
    return s, s.get("still", {})
_, base = still("crf")
ref = base.get("psnr_end_db", 0)
print(f"| link | moving kbit/s | still: PSNR dB 1 s / 3 s after the stop | bytes after the stop | frames after the stop |")
print("|---|---|---|---|---|")
print(f'| crf alone, no rate cap (unshaped) | - | {base.get("psnr_1s_db", 0):.2f} / {base.get("psnr_3s_db", 0):.2f} | {base.get("bytes", 0)} | {base.get("frames", 0)} |')
rows, failed = [], []
for k, (name, rate) in enumerate(zip(names, rates)):
    s, st = still(name)
    link = "unshaped" if rate == "none" else f"{rate} kbit/s ({name[5:]})"
    print(f'| {link} | {s["bytes_per_second"] * 8 / 1000:.0f} | {st.get("psnr_1s_db", 0):.2f} / {st.get("psnr_3s_db", 0):.2f} '
          f'| {st.get("bytes", 0)} | {st.get("frames", 0)} |')
    rows.append({"link": name, "rate_kbit": None if rate == "none" else int(rate), **st})
    last = k == len(names) - 1 and len(names) > 1
    at = st.get("psnr_3s_db" if last else "psnr_1s_db", 0)
    if at < ref - 1.0:
        failed.append(f'{name}: {at:.2f} dB {"3" if last else "1"} s after the stop < {ref:.2f} - 1 (crf, no cap)')
    if s["errors"]: failed.append(f'{name}: {s["errors"]} errors ({s["first_error"]})')
if out:
    json.dump({"crf_no_cap": base, "links": rows}, open(out, "w"), indent=1)
for f in failed: print("FAIL:", f)
sys.exit(1 if check and failed else 0)
PY
  exit $?
fi

run unshaped none
unshaped_kbps=$(python3 -c "import json;print(round(json.load(open('$work/unshaped.json'))['run']['sessions'][0]['bytes_per_second']*8/1000))")
if [ "$beside" -gt 0 ]; then
  f=${fractions##*,}
  r=$(python3 -c "print(max(16, round($unshaped_kbps * $f)))")
  for rate in none "$r"; do
    "$bin/catgs-loadgen" --host "$host_ip" --port "$port" --sessions "$beside" --size 640x360 --trace orbit \
      --rate 60 --decode 1 --seconds "$seconds" --warmup-s "$warmup" --json "$work/beside_$rate.json" \
      > "$work/beside_$rate.txt" 2>&1 &
    fast=$!
    run "slow_$rate" "$rate"
    wait "$fast"
  done
  tc qdisc del dev "$host_if" root 2>/dev/null
  python3 - "$work" "$r" "$beside" <<'PY'
import json, sys
work, rate, n = sys.argv[1], sys.argv[2], sys.argv[3]
print(f"| namespace session's link | {n} sessions beside: p95 ms, FPS min / total | namespace session: p95 ms, FPS, kbit/s |")
print("|---|---|---|")
for r in ("none", rate):
    t = json.load(open(f"{work}/beside_{r}.json"))["run"]["total"]
    s = json.load(open(f"{work}/slow_{r}.json"))["run"]["sessions"][0]
    link = "unshaped" if r == "none" else f"{r} kbit/s"
    print(f'| {link} | {t["latency"]["p95_ms"]:.0f}, {t["fps_min"]:.1f} / {t["fps_total"]:.1f} | '
          f'{s["latency"]["p95_ms"]:.0f}, {s["fps"]:.1f}, {s["bytes_per_second"] * 8 / 1000:.0f} |')
PY
  exit 0
fi
if [ "$step" = 1 ]; then
  f=${fractions##*,}
  r=$(python3 -c "print(max(16, round($unshaped_kbps * $f)))")
  ( sleep 10; tc qdisc add dev "$host_if" root tbf rate "${r}kbit" burst 16kb latency 300ms;
    sleep 10; tc qdisc del dev "$host_if" root ) &
  shaper=$!
  ip netns exec "$ns" "$bin/catgs-loadgen" --host "$host_ip" --port "$port" --sessions 1 --size 640x360 \
    --trace orbit --rate 60 --decode 1 --seconds 30 --receipts "$receipts" --timeline --json "$work/step.json" \
    > "$work/step.txt" 2>&1
  wait "$shaper"
  python3 - "$work" "$unshaped_kbps" "$r" "$json" <<'PY'
import json, sys
work, base_kbps, rate, out = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
unshaped = json.load(open(f"{work}/unshaped.json"))["run"]["sessions"][0]["latency"]
s = json.load(open(f"{work}/step.json"))["run"]["sessions"][0]
tl = s["timeline"]  # [t_s, latency_ms, width, height, bytes]
def window(a, b):
    lat = sorted(f[1] for f in tl if a <= f[0] < b)
    return (lat[int(0.95 * (len(lat) - 1))] if lat else 0, lat[-1] if lat else 0, len(lat))
p95_down, max_down, n_down = window(13, 20)
back = None
for k in range(20, 29):
    kbps = sum(f[4] for f in tl if k <= f[0] < k + 1) * 8 / 1000
    if kbps >= 0.9 * base_kbps:
        back = k + 1 - 20
        break
print(f"| step | unshaped p95 | p95 / max ms, 3-10 s after the step down ({n_down} frames) | back at 90% of {base_kbps:.0f} kbit/s after the step up |")
print("|---|---|---|---|")
print(f"| unshaped -> {rate} kbit/s -> unshaped | {unshaped['p95_ms']:.0f} | {p95_down:.0f} / {max_down:.0f} | "
      f"{'not within 9 s' if back is None else f'{back} s'} |")
if out:
    json.dump({"unshaped_p95_ms": unshaped["p95_ms"], "rate_kbit": rate, "p95_down_ms": p95_down, "max_down_ms": max_down,
               "back_s": back, "timeline": tl}, open(out, "w"))
PY
  exit 0
fi
if [ "$ramp" -gt 0 ]; then
  # One link shared by the ramp's sessions, at the last fraction of MAX unshaped streams: at MAX
  # sessions each one's fair share is that fraction of its stream.
  f=${fractions##*,}
  r=$(python3 -c "print(max(16, round($unshaped_kbps * $f * $ramp)))")
  bound=$(python3 -c "import json;print(round(json.load(open('$work/unshaped.json'))['run']['sessions'][0]['latency']['p95_ms'] + $p95_margin))")
  tc qdisc add dev "$host_if" root tbf rate "${r}kbit" burst 16kb latency 300ms
  ip netns exec "$ns" "$bin/catgs-loadgen" --host "$host_ip" --port "$port" --sessions "$ramp" --ramp \
    --ramp-step +1 --max-p95-ms "$bound" --min-fps 0 --size 640x360 --trace orbit --rate 60 --decode 1 \
    --seconds "$seconds" --warmup-s "$warmup" --receipts "$receipts" --json "$work/ramp.json" > "$work/ramp.txt" 2>&1
  tc qdisc del dev "$host_if" root 2>/dev/null
  echo "one link of $r kbit/s shared by 1..$ramp sessions (bound: p95 <= unshaped + $p95_margin = $bound ms)"
  grep -E "^ramp:" "$work/ramp.txt"
  python3 - "$work" "$r" "$json" <<'PY'
import json, sys
work, rate, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
report = json.load(open(f"{work}/ramp.json"))
print("| sessions | p95 / max ms | FPS min | kbit/s per session, min / total of the link |")
print("|---|---|---|---|")
for step in report["ramp"]:
    t = step["total"]
    kbps = [s["bytes_per_second"] * 8 / 1000 for s in step["sessions"]] or [0]
    print(f'| {len(step["sessions"])} | {t["latency"]["p95_ms"]:.0f} / {t["latency"]["max_ms"]:.0f} | {t["fps_min"]:.1f} '
          f'| {min(kbps):.0f} / {sum(kbps) / rate:.0%} |')
if out:
    json.dump(report, open(out, "w"))
PY
  exit 0
fi
names=(unshaped) rates=(none)
for f in ${fractions//,/ }; do
  r=$(python3 -c "print(max(16, round($unshaped_kbps * $f)))")
  run "link_$f" "$r"
  names+=("link_$f") rates+=("$r")
done
tc qdisc del dev "$host_if" root 2>/dev/null
# The receipts the server read (catgs_frame_receipts_total): with them on, the controller must
# have seen the client's; with --no-receipts, none.
receipts_read=$(get /metrics | sed -n 's/^catgs_frame_receipts_total \([0-9]*\).*/\1/p')

python3 - "$work" "$check" "$json" "$warmup" "${names[*]}" "${rates[*]}" "$p95_margin" "$min_use" "$max_ms" "$min_fps" \
  "$receipts" "${receipts_read:-missing}" <<'PY'
import json, sys
work, check, out, warmup = sys.argv[1], sys.argv[2] == "1", sys.argv[3], float(sys.argv[4])
names, rates = sys.argv[5].split(), sys.argv[6].split()
p95_margin, min_use, max_ms, min_fps = float(sys.argv[7]), float(sys.argv[8]), float(sys.argv[9]), float(sys.argv[10])
receipts_on, receipts_read = sys.argv[11] != "0", sys.argv[12]
rows = []
for name, rate in zip(names, rates):
    s = json.load(open(f"{work}/{name}.json"))["run"]["sessions"][0]
    lat = s["latency"]
    # Where the slowest frame of a pose sent after warm-up (as the latencies) spent its time: in the
    # server (pose received -> handed to the transport: queue, render, convert, encode) or after it
    # (the transport's queue, the link, the decode), and how long the link takes to carry its own
    # bytes; the timeline is [t_s arrived, latency_ms, width, height, bytes, server_ms].
    tl = [f for f in s.get("timeline", []) if f[0] - f[1] / 1000 >= warmup]
    worst = max(tl, key=lambda f: f[1]) if tl else [0, 0, 0, 0, 0, 0]
    server = sorted(f[5] for f in tl) or [0]
    rows.append({"link": name, "rate_kbit": None if rate == "none" else int(rate), "fps": s["fps"],
                 "p50_ms": lat["p50_ms"], "p95_ms": lat["p95_ms"], "p99_ms": lat["p99_ms"], "max_ms": lat["max_ms"],
                 "received_kbit": s["bytes_per_second"] * 8 / 1000, "size_changes": s["size_changes"],
                 "min_size": f'{s["min_width"]}x{s["min_height"]}' if s["size_changes"] else f'{s["width"]}x{s["height"]}',
                 "errors": s["errors"], "first_error": s["first_error"],
                 "limited_stats": s["link_limited_stats"], "cap_min_kbit": s["link_cap_kbps_min"],
                 "slowest": {"latency_ms": worst[1], "server_ms": worst[5], "after_server_ms": worst[1] - worst[5],
                             "bytes": worst[4], "at_s": worst[0],
                             "own_bytes_ms": None if rate == "none" else worst[4] * 8 / int(rate)},
                 "server_p95_ms": server[min(len(server) - 1, int(0.95 * len(server)))]})
print(f"| link | FPS | p50 / p95 / p99 / max ms (after {warmup:g} s) | kbit/s received | link-limited Stats, lowest cap | "
      "slowest frame: in the server / after it ms, bytes (the link carries them in ms) | server p95 ms | smallest size | errors |")
print("|---|---|---|---|---|---|---|---|---|")
for r in rows:
    link = "unshaped" if r["rate_kbit"] is None else f'{r["rate_kbit"]} kbit/s ({r["link"][5:]})'
    print(f'| {link} | {r["fps"]:.1f} | {r["p50_ms"]:.0f} / {r["p95_ms"]:.0f} / {r["p99_ms"]:.0f} / {r["max_ms"]:.0f} '
          f'| {r["received_kbit"]:.0f} | {r["limited_stats"]}, {r["cap_min_kbit"]} '
          f'| {r["slowest"]["server_ms"]:.0f} / {r["slowest"]["after_server_ms"]:.0f}, {r["slowest"]["bytes"]} '
          f'({r["slowest"]["own_bytes_ms"] or 0:.0f}) '
          f'| {r["server_p95_ms"]:.0f} | {r["min_size"]} | {r["errors"]} {r["first_error"]} |')
if out:
    json.dump(rows, open(out, "w"), indent=1)
failed = []
base = rows[0]
for r in rows[1:]:
    if r["p95_ms"] > base["p95_ms"] + p95_margin:
        failed.append(f'{r["link"]}: p95 {r["p95_ms"]:.0f} ms > unshaped {base["p95_ms"]:.0f} + {p95_margin:g}')
    if r["max_ms"] > max_ms: failed.append(f'{r["link"]}: a frame {r["max_ms"]:.0f} ms after its pose (> {max_ms:g} ms)')
    if r["fps"] < min_fps * base["fps"]:
        failed.append(f'{r["link"]}: {r["fps"]:.1f} FPS < {100 * min_fps:g}% of unshaped {base["fps"]:.1f}')
    if r["limited_stats"] == 0: failed.append(f'{r["link"]}: no Stats said the link limited the stream')
    if r["received_kbit"] < min_use * r["rate_kbit"]:
        failed.append(f'{r["link"]}: received {r["received_kbit"]:.0f} kbit/s < {100 * min_use:g}% of the link {r["rate_kbit"]}')
for r in rows:
    if r["errors"]: failed.append(f'{r["link"]}: {r["errors"]} errors ({r["first_error"]})')
frames = sum(json.load(open(f"{work}/{n}.json"))["run"]["sessions"][0]["frames"] for n in names)
print(f"frame receipts the server read: {receipts_read} (of {frames} frames)")
if not receipts_read.isdigit() or (int(receipts_read) < frames // 2 if receipts_on else int(receipts_read) != 0):
    failed.append(f"catgs_frame_receipts_total {receipts_read} with receipts {'on' if receipts_on else 'off'}, {frames} frames")
for f in failed: print("FAIL:", f)
sys.exit(1 if check and failed else 0)
PY
