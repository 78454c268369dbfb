#!/usr/bin/env python3
"""Markdown table of gpu_server_run.sh ramps: one row per ramp (issue 35's table).

usage: ramp_table.py DIR   (DIR/json, or DIR itself, as gpu_server_run.sh ramp writes it, holds
                           ramp-NAME.meta and ramp-NAME_N.json per session count; .gz is read too)

Per ramp: the largest session count that held both bounds, the first step's (one session's)
p95 / p99, and at the largest count held: the slowest session's FPS, pooled p95 / p99, Mbit/s and
bits a pixel per session, the server's mean render / encode / queue ms, the level of detail's
bound (mean and largest, px) and Gaussians a frame where the JSON has them, CPU busy, the server's
CPU (cores) and GPU utilisation; then what broke the next step and the stage that grew most.

A second table follows, one row per step: the sessions that streamed and those refused at the
door, the bounds' numbers, and the encoder's picture (FrameTimings.encode_psnr_db: the coded
frame against the rendered one): its mean over every frame, and the lowest session's mean with
the preset its stream ended at (Stats.encoder), so that a count of visitors comes with the
picture they saw.

A third, one row per step where the JSON has it (issue 92): the render lane's CPU a frame by step
(FrameTimings.lane_{lod,begin,finish}_cpu_ms: the LOD bound's choice, the begin, the finish), the
lanes' cores at the step's frame rate, and the encode call's own thread CPU a frame.
"""
import glob
import gzip
import json
import os
import sys


def open_json(path):
    """A result JSON, plain or gzipped (name ending in .gz)."""
    with (gzip.open(path, "rt") if path.endswith(".gz") else open(path)) as f:
        return json.load(f)


def load(w):
    ramps = []
    d = os.path.join(w, "json") if os.path.isdir(os.path.join(w, "json")) else w
    for meta in sorted(glob.glob(os.path.join(d, "ramp-*.meta")) + glob.glob(os.path.join(d, "ramp-*.meta.gz"))):
        m = open_json(meta)
        steps = []
        for f in glob.glob(os.path.join(d, f"ramp-{m['name']}_*.json")) + glob.glob(
                os.path.join(d, f"ramp-{m['name']}_*.json.gz")):
            n = int(f.removesuffix(".gz").rsplit("_", 1)[1][:-5])
            steps.append((n, open_json(f)))
        steps.sort(key=lambda s: s[0])
        ramps.append((m, steps))
    return ramps


def held(m, j):
    t = j["run"]["total"]
    return not t.get("errors", 0) and t["latency"]["p95_ms"] <= m["p95_bound"] and t["fps_min"] >= m["fps_bound"]


def limit(prev, broke):
    """The stage whose mean grew most from the last held step to the broken one."""
    if broke is None:
        return "not reached"
    a = prev["run"]["total"]["server"] if prev else {}
    b = broke["run"]["total"]["server"]
    growth = {k: b.get(k + "_ms", 0) - a.get(k + "_ms", 0) for k in ("queue", "render", "encode", "send")}
    stage = max(growth, key=growth.get)
    h = broke.get("host", {})
    return (f"{stage} +{growth[stage]:.1f} ms (CPU {100 * h.get('cpu_busy_fraction', 0):.0f}%, "
            f"GPU {h.get('gpu_util_mean') or 0:.0f}%)")


def main(w):
    print("| ramp | scene | size | pipeline | server flags | sessions held | one session p95 / p99 ms | "
          "at the largest held: FPS min, p95 / p99 ms | Mbit/s a session | bits a pixel | render / encode / "
          "queue ms | LOD bound px mean / max, M Gaussians a frame | CPU busy | server CPU (cores) | GPU util | "
          "next step broke by | stage that grew most |")
    print("|" + "---|" * 17)
    for m, steps in load(w):
        if not steps:
            continue
        good = [(n, j) for n, j in steps if held(m, j)]
        n_held, jh = good[-1] if good else (0, None)
        bad = next(((n, j) for n, j in steps if not held(m, j)), (None, None))
        first = steps[0][1]["run"]["total"]["latency"]
        one = f"{first['p95_ms']:.1f} / {first['p99_ms']:.1f}" + ("" if steps[0][0] == 1 else f" (at {steps[0][0]})")
        w_, h_ = (int(x) for x in m["size"].split("x"))
        if jh:
            t = jh["run"]["total"]
            srv, host = t["server"], jh.get("host", {})
            mbps = 8 * t["bytes_per_second"] / n_held / 1e6
            secs = max(s["seconds"] for s in jh["run"]["sessions"])
            at = (f"{t['fps_min']:.1f}, {t['latency']['p95_ms']:.1f} / {t['latency']['p99_ms']:.1f}", f"{mbps:.1f}",
                  f"{mbps * 1e6 / (w_ * h_ * 60):.3f}",
                  f"{srv['render_ms']:.2f} / {srv['encode_ms']:.2f} / {srv['queue_ms']:.2f}",
                  (f"{srv['lod_error_px_mean']:.2f} / {srv['lod_error_px_max']:.2f}, {srv['splats_mean'] / 1e6:.2f}"
                   if srv.get("lod_error_px_max") else "-"),
                  f"{100 * host.get('cpu_busy_fraction', 0):.0f}%", f"{host.get('server_cpu_seconds', 0) / secs:.1f}",
                  f"{host.get('gpu_util_mean') or 0:.0f}%")
        else:
            at = ("none held",) + ("",) * 7
        broke = ""
        if bad[1] is not None:
            t = bad[1]["run"]["total"]
            broke = (f"{bad[0]}: p95 {t['latency']['p95_ms']:.1f} ms, slowest {t['fps_min']:.1f} FPS"
                     + (f", {t['errors']} errors" if t.get("errors") else ""))
        print(f"| {m['name']} | {m['scene']} | {m['size']} | {m['pipeline']} | {m['args'] or 'defaults'} | {n_held} | "
              f"{one} | " + " | ".join(at) + f" | {broke} | {limit(jh, bad[1])} |")

    print()
    print("| ramp | sessions | refused | held | p95 ms | slowest FPS | encoder picture dB, mean | "
          "lowest session dB (its preset) |")
    print("|" + "---|" * 8)
    for m, steps in load(w):
        for n, j in steps:
            t = j["run"]["total"]
            pic = t["server"].get("encode_psnr_db_mean", 0)
            streams = [s for s in j["run"]["sessions"] if s.get("server", {}).get("encode_psnr_db_mean", 0) > 0]
            low = min(streams, key=lambda s: s["server"]["encode_psnr_db_mean"]) if streams else None
            lowest = f"{low['server']['encode_psnr_db_mean']:.2f} ({low.get('stream_encoder', '')})" if low else "-"
            print(f"| {m['name']} | {n} | {t.get('refused', 0)} | {'yes' if held(m, j) else 'no'} | "
                  f"{t['latency']['p95_ms']:.1f} | {t['fps_min']:.1f} | {pic:.2f} | {lowest} |")

    # Where a frame's host CPU goes, by thread (issue 92; FrameTimings' thread clocks): the render
    # lane's three steps and the encode call's own thread (x264's slice threads not counted).
    print()
    print("| ramp | sessions | lane: LOD bound ms | lane: begin ms | lane: finish ms | lane cores at the frame rate "
          "| encode call thread ms |")
    print("|" + "---|" * 7)
    for m, steps in load(w):
        for n, j in steps:
            t = j["run"]["total"]
            srv = t["server"]
            if "lane_begin_cpu_ms" not in srv:
                continue
            lane = srv["lane_lod_cpu_ms"] + srv["lane_begin_cpu_ms"] + srv["lane_finish_cpu_ms"]
            fps = sum(x.get("frames", 0) / max(x.get("seconds", 1), 1e-9) for x in j["run"]["sessions"])
            print(f"| {m['name']} | {n} | {srv['lane_lod_cpu_ms']:.3f} | {srv['lane_begin_cpu_ms']:.3f} | "
                  f"{srv['lane_finish_cpu_ms']:.3f} | {lane * fps / 1000:.2f} | {srv.get('encode_thread_cpu_ms', 0):.3f} |")


if __name__ == "__main__":
    main(sys.argv[1])
