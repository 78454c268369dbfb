#!/usr/bin/env python3
"""Issue 36, second round: what a cap on a key frame's trail list would have done, simulated from
the first round's per-frame data (final_run2/: exact and catgs at the same poses; commit 2214945
holds the whole run as issue36/final_run2.tar.gz).

A group is a run of frames with the same catgs list length (a key frame and its sub-frames).
When the key frame's list is over CAP times the exact list of the same pose, the key frame
becomes a full frame (the exact frame's time plus half the speculative pre-processing's stage
mean, already spent when the count comes back) and its sub-frames full frames too.
Usage: sim_list_cap.py DIR (compare_*.json or compare_*.json.gz, e.g. final_run2/ beside this file)."""
import glob
import gzip
import json
import os
import sys


def p99(xs):
    y = sorted(xs)
    k = (len(y) - 1) * 0.99
    f = int(k)
    c = min(f + 1, len(y) - 1)
    return y[f] + (y[c] - y[f]) * (k - f)


def groups(lists):
    i = 0
    while i < len(lists):
        j = i + 1
        while j < len(lists) and lists[j] == lists[i]:
            j += 1
        yield i, j
        i = j


for path in sorted(glob.glob(os.path.join(sys.argv[1], "compare_*.json*")), key=lambda p: p.removesuffix(".gz")):
    with (gzip.open(path, "rt") if path.endswith(".gz") else open(path)) as f:
        runs = {p["pipeline"]: p for p in json.load(f)["pipelines"]}
    em, el = runs["exact"]["per_frame_ms"], runs["exact"]["per_frame_render_list"]
    cm, cl = runs["catgs"]["per_frame_ms"], runs["catgs"]["per_frame_render_list"]
    spent = 0.5 * runs["catgs"]["stages_ms_mean"]["preprocess"]
    cells = []
    for cap in (None, 1.5, 2.0, 2.5):
        ms = list(cm)
        for i, j in groups(cl):
            if cap is not None and j - i > 1 and cl[i] / el[i] > cap:
                ms[i] = em[i] + spent
                ms[i + 1:j] = em[i + 1:j]
        cells.append("%.2f / %.2f" % (sum(em) / sum(ms), p99(ms) / p99(em)))
    print("| %s | %s |" % (os.path.basename(path).removesuffix(".gz")[8:-5], " | ".join(cells)))
