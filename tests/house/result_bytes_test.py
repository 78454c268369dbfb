#!/usr/bin/env python3
"""Result files stay a small share of the repository (ctest house_result_bytes, label house).

Result files: every tracked file under a directory named `results`, anywhere in the tree
(tests/gpu/results/, tests/results/ and any later one). Tracked bytes: the sizes of all files
`git ls-files -z` lists (as they are in the work tree; a listed file the work tree lacks counts 0).
The test fails when result files pass LIMIT percent of the tracked bytes (default 15): a result
folder holds tables and small summaries that RESULTS.md, tests/gpu/RESULTS.md and docs/history/
cite, not the raw dumps the scripts write again (tests/gpu/results/README.md).

usage: result_bytes_test.py [--source-dir DIR] [--limit PERCENT] [--worktree]
  --worktree  also count files git does not track yet but would (not ignored): the share the
              next commit would have, for checking before staging.
Exit 0 within the limit, 1 past it, 77 (skip) where DIR is not a git checkout or git is missing.
"""
import argparse
import os
import subprocess
import sys

SKIP = 77


def listed_files(source_dir, worktree):
    cmd = ["git", "-C", source_dir, "ls-files", "-z", "--cached"]
    if worktree:
        cmd += ["--others", "--exclude-standard"]
    out = subprocess.run(cmd, check=True, capture_output=True).stdout
    return sorted({p.decode("utf-8", "surrogateescape") for p in out.split(b"\0") if p})


def result_folder(path):
    """The folder a result file is counted in: the `results` directory's child it lies under
    (tests/gpu/results/encoding), or the `results` directory itself for a file directly in it;
    None for a file that is not a result file."""
    parts = path.split("/")
    for i, part in enumerate(parts[:-1]):
        if part == "results":
            return "/".join(parts[: i + 2]) if i + 2 < len(parts) else "/".join(parts[: i + 1])
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--source-dir", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
    ap.add_argument("--limit", type=float, default=15.0, help="percent of the tracked bytes (default 15)")
    ap.add_argument("--worktree", action="store_true", help="count untracked, not ignored files too")
    args = ap.parse_args()
    src = os.path.abspath(args.source_dir)

    try:
        inside = subprocess.run(["git", "-C", src, "rev-parse", "--is-inside-work-tree"], capture_output=True, text=True)
    except FileNotFoundError:
        print("SKIP: git is not installed, so the tracked files cannot be listed")
        return SKIP
    if inside.returncode != 0 or inside.stdout.strip() != "true":
        print(f"SKIP: {src} is not a git checkout (no tracked files to count)")
        return SKIP

    total = 0
    results = 0
    folders = {}
    for path in listed_files(src, args.worktree):
        full = os.path.join(src, path)
        if not os.path.lexists(full):
            continue
        size = os.lstat(full).st_size
        total += size
        folder = result_folder(path)
        if folder is not None:
            results += size
            folders[folder] = folders.get(folder, 0) + size

    share = 100.0 * results / total if total else 0.0
    what = "tracked and to-be-tracked" if args.worktree else "tracked"
    print(f"result files (under a folder named results): {results} bytes ({results / 1e6:.2f} MB)")
    print(f"{what} files: {total} bytes ({total / 1e6:.2f} MB)")
    print(f"share: {share:.1f}% (limit {args.limit:g}%)")
    print("largest result folders:")
    for folder, size in sorted(folders.items(), key=lambda kv: (-kv[1], kv[0]))[:5]:
        print(f"  {size:>10} bytes  {folder}")
    if share > args.limit:
        print(f"FAIL: result files are {share:.1f}% of the {what} bytes, over {args.limit:g}%. Keep tables and "
              "small gzipped summaries; leave raw per-step dumps, server logs, archives of runs and per-frame "
              "arrays out (the scripts write them again; tests/gpu/results/README.md)")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
