#!/usr/bin/env python3
"""Markdown table of gpu_server_run.sh ramps, step by step, for device memory (issue 61).

usage: ramp_memory_table.py DIR   (DIR/json, or DIR itself, holds ramp-NAME.meta and
                                  ramp-NAME_N.json per session count; .gz is read too)

One row per ramp step: sessions asked for, refused at the door (ERROR_SERVER_FULL) and failed
(ended by an error), the pooled p95 pose-to-frame and the slowest session's FPS, the most device
memory a session held (Stats.device_memory_mib, catgs-loadgen's device_memory_mib_max) and the
GPU's memory in use (nvidia-smi every 200 ms, the step's largest), and the first refusal's reason.
"""
import glob
import os
import re
import sys

from ramp_table import open_json


def main():
    w = sys.argv[1]
    d = os.path.join(w, "json") if os.path.isdir(os.path.join(w, "json")) else w
    print("| ramp | sessions | refused | failed | p95 ms | slowest FPS | session MiB (most) | GPU MiB in use | refusal |")
    print("|---|---|---|---|---|---|---|---|---|")
    for meta in sorted(glob.glob(os.path.join(d, "ramp-*.meta*"))):
        name = re.sub(r"\.meta(\.gz)?$", "", os.path.basename(meta))[len("ramp-"):]
        steps = []
        for path in glob.glob(os.path.join(d, "ramp-%s_*.json*" % name)):
            m = re.search(r"_(\d+)\.json", path)
            if m:
                steps.append((int(m.group(1)), path))
        for n, path in sorted(steps):
            j = open_json(path)
            t = j["run"]["total"]
            sessions = j["run"].get("sessions", [])
            most = max((s.get("device_memory_mib_max", 0) for s in sessions), default=0)
            reason = next((s["refusal"] for s in sessions if s.get("refusal")), "")
            gpu = (j.get("host") or {}).get("gpu_memory_used_mib_max")
            print("| %s | %d | %d | %d | %.1f | %.1f | %d | %s | %s |" % (
                name, n, t.get("refused", 0), t.get("failed", 0), t["latency"]["p95_ms"], t["fps_min"], most,
                "%.0f" % gpu if gpu is not None else "-", reason[:160].replace("|", "/")))


if __name__ == "__main__":
    main()
