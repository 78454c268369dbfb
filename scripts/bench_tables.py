#!/usr/bin/env python3
"""Markdown tables (issue 4's report) from the catgs-bench JSON files of one gpu_run.sh run.

usage: scripts/bench_tables.py DIR    (DIR holds bench_*.json, e.g. bench.tar.gz unpacked, or
                                       compare_*.json from --compare; .json.gz is read too)

Prints: FPS per scene x path with the ratios to exact and vanilla (Tables 1/3), key vs
sub-frames with render-list growth and sub-frame quality, the stages of key and sub-frames
(Table 5) and, when bench_windows_*.json are there, the window table (Table 6).
"""
import glob
import gzip
import json
import os
import sys

SCENES = {"tumblewood": "tumblewood_sh2 x10 (542 k)", "city": "city (7.05 M)"}


def open_json(path):
    """A result JSON, plain or gzipped (name ending in .gz)."""
    with (gzip.open(path, "rt") if path.endswith(".gz") else open(path)) as f:
        return json.load(f)


def load(directory):
    runs = []
    paths = glob.glob(os.path.join(directory, "*.json")) + glob.glob(os.path.join(directory, "*.json.gz"))
    for path in sorted(paths, key=lambda p: os.path.basename(p).removesuffix(".gz")):
        stem = os.path.basename(path).removesuffix(".gz")[:-5]
        kind, _, rest = stem.partition("_")
        scene, _, trace = rest.partition("_")
        runs.append((kind, scene, trace, open_json(path)))
    return runs


def by_name(run):
    return {p["pipeline"]: p for p in run["pipelines"]}


def fps_table(runs):
    names = []
    for kind, scene, _, run in runs:
        if scene != "windows":
            for p in run["pipelines"]:
                if p["pipeline"] not in names:
                    names.append(p["pipeline"])
    print("| scene | camera path | " + " | ".join(names) + " | catgs / exact | catgs / vanilla |")
    print("|---|---|" + "---|" * len(names) + "---|---|")
    for kind, scene, trace, run in runs:
        if kind == "bench" and scene == "windows":
            continue
        ps = by_name(run)
        cells = []
        for n in names:
            p = ps.get(n)
            cells.append(f"{p['fps']:.0f} ({p['frame_ms']['mean']:.2f})" if p else "")
        ratio = lambda a, b: f"x{ps[a]['fps'] / ps[b]['fps']:.2f}" if a in ps and b in ps else ""
        print(f"| {SCENES.get(scene, scene)} | {trace} | " + " | ".join(cells) +
              f" | {ratio('catgs', 'exact')} | {ratio('catgs', 'vanilla')} |")


def key_sub_table(runs):
    print("| scene | camera path | pipeline | key frames | sub-frames | mean W | key ms | sub ms | sub / key |"
          " key list / exact list (mean, max) | sub-frame PSNR vs full render (mean, min) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for kind, scene, trace, run in runs:
        if scene == "windows":
            continue
        for p in run["pipelines"]:
            if not p["pipeline"].startswith("catgs") or p["pipeline"] == "catgs-nocache":  # no sub-frames
                continue
            k, s = p["key_frames"], p["sub_frames"]
            g, q = p["key_list_growth_vs_exact"], p["subframe_quality_vs_full_render"]
            ratio = f"{100 * s['mean_ms'] / k['mean_ms']:.0f}%" if s["count"] else ""
            qual = (f"{q['psnr_db_mean_finite']:.1f}, {q['psnr_db_min']:.1f} dB ({q['compared']})"
                    if q.get("compared") else "")
            print(f"| {scene} | {trace} | {p['pipeline']} | {k['count']} | {s['count']} | {p['window_mean']:.2f} |"
                  f" {k['mean_ms']:.3f} | {s['mean_ms']:.3f} | {ratio} | {g.get('mean', 0):.2f}, {g.get('max', 0):.2f} |"
                  f" {qual} |")


STAGES = ["preprocess", "keys", "sort", "tile_ranges", "rasterize", "merge"]


def stage_table(runs):
    print("| scene, path | pipeline | frame ms | pre-processing | key emission | sort | tile ranges (+ cache, split"
          " plan) | rasterization | merge |")
    print("|---|---|---|---|---|---|---|---|---|")
    for kind, scene, trace, run in runs:
        if scene == "windows":
            continue
        for p in run["pipelines"]:
            n = p["pipeline"]
            if n in ("vanilla", "exact"):
                rows = [(n, p["frame_ms"]["mean"], p["stages_ms_mean"])]
            elif n == "catgs":
                rows = [("catgs key", p["key_frames"]["mean_ms"], p["key_frames"]["stages_ms_mean"]),
                        ("catgs sub", p["sub_frames"]["mean_ms"], p["sub_frames"]["stages_ms_mean"])]
            else:
                continue
            for label, ms, st in rows:
                cells = [f"{st[s]:.3f}" if st.get(s) else "-" for s in STAGES]
                print(f"| {scene}, {trace} | {label} | {ms:.3f} | " + " | ".join(cells) + " |")


def window_table(runs):
    print("| scene | pipeline | FPS | render list mean (max) | key list / exact list mean | key / sub frames |"
          " mean W | sub / key cost | sub-frame PSNR mean, min |")
    print("|---|---|---|---|---|---|---|---|---|")
    for kind, scene, trace, run in runs:
        if scene != "windows":
            continue
        for p in run["pipelines"]:
            rl = p["render_list"]
            row = f"| {trace} | {p['pipeline']} | {p['fps']:.0f} | {rl['mean'] / 1e6:.2f} M ({rl['max'] / 1e6:.2f} M) |"
            if p["pipeline"] == "exact":
                print(row + " 1 | | | | |")
                continue
            q = p["subframe_quality_vs_full_render"]
            print(row + f" {p['key_list_growth_vs_exact'].get('mean', 0):.2f} |"
                  f" {p['key_frames']['count']} / {p['sub_frames']['count']} | {p['window_mean']:.2f} |"
                  f" {100 * p['sub_over_key_cost']:.0f}% |"
                  f" {q.get('psnr_db_mean_finite', 0):.1f}, {q.get('psnr_db_min', 0):.1f} |")


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    runs = load(sys.argv[1])
    if not runs:
        sys.exit(f"bench_tables.py: no JSON files in {sys.argv[1]}")
    print(f"GPU: {runs[0][3]['gpu']}; {runs[0][3]['width']}x{runs[0][3]['height']}, "
          f"{runs[0][3]['frames']} timed frames after {runs[0][3]['warmup']} warm-up\n")
    print("### FPS (mean frame time in ms in brackets)\n")
    fps_table(runs)
    print("\n### Key vs sub-frames\n")
    key_sub_table(runs)
    print("\n### Stages, ms per frame (catgs: key frames and sub-frames apart)\n")
    stage_table(runs)
    if any(scene == "windows" for _, scene, _, _ in runs):
        print("\n### Window sizes (bicycle path)\n")
        window_table(runs)


if __name__ == "__main__":
    main()
