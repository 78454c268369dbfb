#!/usr/bin/env python3
"""Markdown table of a gpu_server_run.sh sweep: one row per (scene, size, sessions) loadgen JSON.

usage: sweep_table.py DIR   (DIR holds json/SCENE_WxH_N.json (or .json.gz), gpu.txt, cores.txt)
"""
import gzip
import json
import os
import sys


def main(w):
    gpu = open(os.path.join(w, "gpu.txt")).read().strip()
    cores = open(os.path.join(w, "cores.txt")).read().strip()
    rows = []
    for f in os.listdir(os.path.join(w, "json")):
        path = os.path.join(w, "json", f)
        with (gzip.open(path, "rt") if f.endswith(".gz") else open(path)) as fh:
            j = json.load(fh)
        scene, size, n = f.removesuffix(".gz")[:-5].split("_")
        rows.append((scene, int(size.split("x")[1]), int(n), size, j))
    rows.sort(key=lambda r: r[:3])
    s0 = rows[0][4]["run"]["sessions"][0] if rows else {}
    print(f"GPU: {gpu}; {cores} cores; renderer {s0.get('renderer')}, encoder {s0.get('encoder')}; "
          f"scene-PIPELINE per row; 60 poses/s per session; latency = pose sent -> frame received\n")
    print("| scene | size | sessions | FPS min | FPS mean | p50 ms | p95 ms | p99 ms | render ms | key % | "
          "convert ms | encode ms | queue ms | send ms | dropped | CPU busy | server CPU (cores) | GPU util |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    alone = {}
    for scene, _, n, size, j in rows:
        t = j["run"]["total"]
        lat, srv, h = t["latency"], t["server"], j["host"]
        secs = max(1e-9, max(s["seconds"] for s in j["run"]["sessions"]))
        if n == 1:
            alone[(scene, size)] = srv["render_ms"]
        gu = h.get("gpu_util_mean")
        print(f"| {scene} | {size} | {n} | {t['fps_min']:.1f} | {t['fps_total'] / n:.1f} | {lat['p50_ms']:.1f} | "
              f"{lat['p95_ms']:.1f} | {lat['p99_ms']:.1f} | {srv['render_ms']:.2f} | {100 * srv['render_key_fraction']:.0f} | "
              f"{srv['convert_ms']:.2f} | {srv['encode_ms']:.2f} | {srv['queue_ms']:.2f} | {srv['send_ms']:.2f} | "
              f"{t['dropped']} | {100 * h['cpu_busy_fraction']:.0f}% | {h['server_cpu_seconds'] / secs:.1f} | "
              f"{'%.0f%%' % gu if gu is not None else 'n/a'} |")
    print("\nRender time per frame with N sessions running, over running alone (same scene and size):\n")
    for scene, _, n, size, j in rows:
        a = alone.get((scene, size))
        if a and n > 1:
            print(f"- {scene} {size} x{n}: {j['run']['total']['server']['render_ms'] / a:.2f}x")


if __name__ == "__main__":
    main(sys.argv[1])
