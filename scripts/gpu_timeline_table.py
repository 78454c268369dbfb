#!/usr/bin/env python3
"""Markdown table of the GPU timeline under load (issue 47): per ramp and step, the renderer's own
stage times and each render lane's frames, from gpu_server_run.sh ramps.

usage: gpu_timeline_table.py DIR   (as scripts/ramp_table.py: DIR/json or DIR holds ramp-NAME.meta
                                    and ramp-NAME_N.json per session count; .gz is read too)

Per step: sessions, the slowest session's FPS, pooled p95, the pose's wait before its render (and
the part of it the job waited for a lane: FrameTimings.lane_wait_ms; "-" before it existed), the
server's render ms (host clock, pose
taken to planes on the host), the renderer's frame and stage ms (FrameTimings.stage_*_ms: CUDA
events on the session's stream, so under load they include the time its kernels shared the GPU
with the other lanes' frames), each lane's share of the frames and mean frame ms, the host's
GPU utilisation, and the server's three busiest threads with their share of a core over the step
(gpu_server_run.sh thread_times; catgs-lws: the transport's service thread, catgs-laneN: render
lanes, catgs-poolN: Asio workers and the x264 threads their encoders started). Steps from before
the fields existed show "-".
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ramp_table import load  # noqa: E402

STAGES = ("frame", "preprocess", "keys", "sort", "ranges", "rasterize")


def main(w):
    print("| ramp | sessions | FPS min | p95 ms | queue ms (of it for a lane) | render ms (host) | renderer frame ms | "
          "preprocess / keys / sort / ranges / rasterize ms | lanes: share of frames, frame ms | GPU util | busiest threads |")
    print("|" + "---|" * 11)
    for m, steps in load(w):
        for n, j in steps:
            t = j["run"]["total"]
            srv, host = t["server"], j.get("host", {})
            st = srv.get("render_stages_ms")
            lanes = srv.get("render_lanes") or []
            frames = sum(l["frames"] for l in lanes) or 1
            lane_text = "; ".join(f"{l['lane']}: {100 * l['frames'] / frames:.0f}%, {l['frame_ms_mean']:.2f}"
                                  for l in lanes) or "-"
            stage_text = " / ".join(f"{st[k]:.2f}" for k in STAGES[1:]) if st else "-"
            lane_wait = srv.get("lane_wait_ms")
            queue = f"{srv['queue_ms']:.2f} ({lane_wait:.2f})" if lane_wait is not None else f"{srv['queue_ms']:.2f} (-)"
            busiest = "; ".join(f"{name} {100 * f:.0f}%" for name, f in host.get("server_threads_busiest", [])[:3]) or "-"
            print(f"| {m['name']} | {n} | {t['fps_min']:.1f} | {t['latency']['p95_ms']:.1f} | {queue} | {srv['render_ms']:.2f} | "
                  f"{st['frame']:.2f} | {stage_text} | {lane_text} | {host.get('gpu_util_mean') or 0:.0f}% | {busiest} |"
                  if st else
                  f"| {m['name']} | {n} | {t['fps_min']:.1f} | {t['latency']['p95_ms']:.1f} | {queue} | {srv['render_ms']:.2f} | "
                  f"- | - | - | {host.get('gpu_util_mean') or 0:.0f}% | {busiest} |")


if __name__ == "__main__":
    main(sys.argv[1])
