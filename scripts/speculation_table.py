#!/usr/bin/env python3
"""Per-step speculation figures of gpu_server_run.sh ramps (issue 48): one row per ramp step.

usage: speculation_table.py DIR [NAME ...]   (DIR/json or DIR as ramp_table.py reads it; NAME: the
                                              ramps to show, all by default)

Per step: sessions, pooled p95 / p99 pose-to-frame ms, the slowest session's FPS, the server's mean
render ms, and for each real path (the sessions on it pooled) the share of sub-frames, of re-keys
(key frames first tried as sub-frames) and the mean speculation window W.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ramp_table import held, load  # noqa: E402


def path_name(trace):
    base = os.path.basename(trace).removesuffix(".trace")
    for p in ("mipnerf360_bicycle", "tandt_train", "flowers_sh3"):
        if base.endswith(p):
            return p.removeprefix("mipnerf360_")
    return base


def per_path(j):
    """{path: (frames, sub share, re-key share, mean W)} pooled over the sessions on each path."""
    sums = {}
    for s in j["run"]["sessions"]:
        srv = s["server"]
        n = srv.get("frames", 0)
        a = sums.setdefault(path_name(s["trace"]), [0, 0.0, 0.0, 0.0])
        a[0] += n
        a[1] += n * srv.get("render_sub_fraction", 1.0 - srv["render_key_fraction"])
        a[2] += n * srv.get("render_rekey_fraction", 0.0)
        a[3] += n * srv.get("speculation_window_mean", 0.0)
    return {p: (n, sub / n, rekey / n, w / n) for p, (n, sub, rekey, w) in sums.items() if n}


def main(d, names):
    print("| ramp | sessions | held | p95 / p99 ms | slowest FPS | render ms | "
          "sub-frames / re-keys / W by path |")
    print("|---|---|---|---|---|---|---|")
    for m, steps in load(d):
        if names and m["name"] not in names:
            continue
        for n, j in steps:
            t = j["run"]["total"]
            paths = per_path(j)
            cells = "; ".join(f"{p} {100 * sub:.0f}% / {100 * rk:.0f}% / {w:.2f}"
                              for p, (_, sub, rk, w) in sorted(paths.items()))
            print(f"| {m['name']} | {n} | {'yes' if held(m, j) else 'no'} | "
                  f"{t['latency']['p95_ms']:.1f} / {t['latency']['p99_ms']:.1f} | {t['fps_min']:.1f} | "
                  f"{t['server']['render_ms']:.2f} | {cells} |")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1], set(sys.argv[2:]))
