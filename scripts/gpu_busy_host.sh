#!/usr/bin/env bash
# scripts/gpu_busy_host.sh (issue 64): on the GPU machine, a loaded host's clients are not slow
# links. The 13-copy city at 720p (exact), catgs-loadgen on the same host, COUNTS sessions (default
# 36 40 44 48, 6 s a step, no bound: every step runs); per step the sessions the link controller
# limited, the lowest cap, the cuts by cause (/metrics) and the client's late reads and receipts
# -> $OUT/busy_diag.md and .json. Side by side with an older build when .carry_busy/old.tar.xz
# holds one (old/catgs-server, old/catgs-loadgen, stripped, tar.xz), else this build alone.
# Carry [".carry_srv", ".carry_busy"] (scripts/gpu_server_run.sh prepare; the script reads the
# old build from .carry_busy/ when it is there).
#   usage (on the GPU machine): bash scripts/gpu_busy_host.sh
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"
SRV=/tmp/catgs_srv W=/tmp/catgs_sweep
bash scripts/gpu_server_run.sh unpack > /dev/null || exit 1
bash scripts/gpu_server_run.sh scenes > /dev/null || exit 1
mkdir -p $SRV/new && cp $SRV/bin/catgs-server $SRV/bin/catgs-loadgen $SRV/new/
builds=new
if [ -f .carry_busy/old.tar.xz ]; then
  xz -dc .carry_busy/old.tar.xz | tar -C $SRV -xf - || exit 1
  builds="old new"
fi
export LD_LIBRARY_PATH=$SRV/lib
traces="$W/city_mipnerf360_bicycle.trace,$W/city_tandt_train.trace,$W/city_flowers_sh3.trace"
metrics() { python3 -c "import urllib.request;print(urllib.request.urlopen('http://127.0.0.1:18080/metrics').read().decode())"; }
for v in $builds; do
  $SRV/$v/catgs-server --scene $W/city.compressed.ply --port 18080 --renderer cuda --pipeline exact --encoder auto \
    --max-sessions 64 > "$OUT/server-$v.log" 2>&1 &
  pid=$!
  for _ in $(seq 300); do
    python3 -c "import urllib.request,sys;sys.exit(0 if urllib.request.urlopen('http://127.0.0.1:18080/readyz').status==200 else 1)" 2>/dev/null && break
    sleep 0.5
  done
  metrics > "$OUT/metrics-$v-0.txt"
  for n in ${COUNTS:-36 40 44 48}; do
    $SRV/$v/catgs-loadgen --port 18080 --sessions $n --size 1280x720 --trace "$traces" --rate 60 --seconds 6 \
      --warmup 30 --progress 0 --json "$OUT/busy-$v-$n.json" > "$OUT/load-$v-$n.txt" 2>&1
    metrics > "$OUT/metrics-$v-$n.txt"
    echo "$v $n done"
  done
  kill $pid; wait $pid 2>/dev/null
done
python3 - "$OUT" "${COUNTS:-36 40 44 48}" "$builds" <<'PY' | tee "$OUT/busy_diag.md"
import json, re, sys
out, counts, builds = sys.argv[1], [int(c) for c in sys.argv[2].split()], sys.argv[3].split()
def metric(text, series):
    m = re.search(r'^' + re.escape(series) + r' ([0-9.eE+-]+)$', text, re.M)
    return float(m.group(1)) if m else None
print("| server and loadgen | sessions | p95 ms | slowest FPS | sessions link-limited | lowest cap kbit/s | cuts: send delay / receipts / round trip | late reads / receipts sent |")
print("|---|---|---|---|---|---|---|---|")
rows = []
for v in builds:
    prev = open(f"{out}/metrics-{v}-0.txt").read()
    for n in counts:
        cur = open(f"{out}/metrics-{v}-{n}.txt").read()
        j = json.load(open(f"{out}/busy-{v}-{n}.json")); t = j["run"]["total"]; ss = j["run"]["sessions"]
        lim = sum(1 for s in ss if s.get("link_limited_stats", 0) > 0)
        caps = [s["link_cap_kbps_min"] for s in ss if s.get("link_cap_kbps_min", 0) > 0]
        cuts = metric(cur, "catgs_link_rate_decreases_total") - metric(prev, "catgs_link_rate_decreases_total")
        by = []
        for c in ("send_delay", "receipts", "round_trip"):
            a, b = metric(cur, f'catgs_link_rate_cuts_total{{cause="{c}"}}'), metric(prev, f'catgs_link_rate_cuts_total{{cause="{c}"}}')
            by.append(None if a is None else a - b)
        late = sum(s.get("late_reads", 0) for s in ss); sent = sum(s.get("receipts_sent", 0) for s in ss)
        row = {"server": v, "sessions": len(ss), "p95_ms": t["latency"]["p95_ms"], "fps_min": t["fps_min"],
               "link_limited_sessions": lim, "cap_min_kbps": min(caps) if caps else 0, "cuts": cuts, "cuts_by_cause": by,
               "late_reads": late if v == "new" else None, "receipts_sent": sent if v == "new" else None}
        rows.append(row)
        bys = f"{cuts:.0f} (" + " / ".join("-" if x is None else f"{x:.0f}" for x in by) + ")"
        print(f'| {"landed" if v == "old" else "this commit"} | {len(ss) - t.get("refused", 0)} | {t["latency"]["p95_ms"]:.1f} | {t["fps_min"]:.1f} | '
              f'{lim} | {min(caps) if caps else "-"} | {bys} | {f"{late} / {sent}" if v == "new" else "-"} |')
        prev = cur
json.dump(rows, open(f"{out}/busy_diag.json", "w"), indent=1)
PY
