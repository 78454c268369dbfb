#!/usr/bin/env python3
"""The documents hold by the code (issue 75; ctest house_documents, label house).

Checks, each failure printed with the file and the offending name:
  lines     RESULTS.md and tests/gpu/RESULTS.md have at most 400 lines each (the results page is
            today's numbers; what came before lives in docs/history/).
  flags     every --flag that README.md and the component READMEs name is one some program
            of ours offers: in the --help of the programs in BIN_DIR, or in the text of the
            scripts and test drivers that take it (scripts/, tests/**/*.sh, tests/e2e/*.mjs),
            or one of the outside tools' flags listed below (EXTERNAL_FLAGS).
  paths     every repository path they name (in `code` or as a link target) exists: relative to
            the repository, to the README's folder or to one of the include roots (server/,
            render_core/, tools/, web_client/, tests/). Build outputs, the data folder and
            names with placeholders (NAME, *, {a,b}, <x>) are not paths of the repository.
  layering  inside render_core/ and server/ a room includes only rooms below it in README.md's
            "Layout" table, except the includes listed in LAYERING_EXCEPTIONS (each says why).

usage: documents_test.py [--source-dir DIR] [--bin-dir DIR] [--only lines,flags,paths,layering]
Exit 0 when every check holds, 1 otherwise; without --bin-dir the flags check reads no --help
(and says so).
"""
import argparse
import os
import re
import subprocess
import sys

MAX_LINES = 400
READMES = [
    "README.md", "server/README.md", "render_core/README.md", "tools/README.md", "web_client/README.md",
    "deploy/README.md", "tests/e2e/README.md", "tests/fuzz/README.md", "tests/results/README.md",
]
PROGRAMS = ["catgs-server", "catgs-loadgen", "catgs-bench", "catgs-scene", "catgs-render", "catgs-encode-bench", "catgs-shown"]
# Flags of tools that are not ours, named in the READMEs where they say how to run them.
EXTERNAL_FLAGS = {
    "--build-arg", "--cap-drop", "--context-only", "--digestfile", "--rm", "--network", "--security-opt",  # podman
    "--preset", "--build", "--test-dir", "--output-on-failure", "--target", "--parallel",  # cmake, ctest
    "--gtest_filter", "--gtest_list_tests",  # GoogleTest
    "--test", "--no-install-recommends",  # node, apt
    "--encode",  # protoc
}
# Paths the READMEs name that are other projects' (a library's source file, an image).
EXTERNAL_PATHS = {"lib/roles/ws/ops-ws.c", "nvidia/cuda"}
# Includes against the Layout table's order, each with its reason.
LAYERING_EXCEPTIONS = {
    ("render_core/renderer", "render_core/cpu"): "the renderer factory picks a core",
    ("render_core/renderer", "render_core/cuda"): "the renderer factory picks a core",
    ("render_core/cpu", "render_core/renderer"): "the CPU core implements the Renderer interface",
    ("render_core/cuda", "render_core/renderer"): "the CUDA core implements the Renderer interface",
    ("server/session", "server/transport"): "a session sends through its connection (connection_link.h, the "
                                            "transport's interface) and reads the link's rate (TCP_INFO)",
    ("server/render", "server/process"): "the render lanes name their threads (process/thread_name.h)",
    ("server", "*"): "the server owns every room (server.h, server_options.h, main.cpp)",
}


def read(path):
    with open(path, encoding="utf-8") as f:
        return f.read()


def check_lines(root):
    bad = []
    for rel in ["RESULTS.md", "tests/gpu/RESULTS.md"]:
        n = read(os.path.join(root, rel)).count("\n")
        if n > MAX_LINES:
            bad.append(f"{rel}: {n} lines (at most {MAX_LINES}; move what came before to docs/history/)")
    return bad


def known_flags(root, bin_dir):
    text = []
    if bin_dir:
        for p in PROGRAMS:
            exe = os.path.join(bin_dir, p)
            if not os.path.exists(exe):
                continue
            r = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=30)
            text.append(r.stdout + r.stderr)
    for folder, exts in [("scripts", (".sh", ".py")), ("tests", (".sh", ".mjs"))]:
        for dirpath, dirs, files in os.walk(os.path.join(root, folder)):
            dirs[:] = [d for d in dirs if d != "node_modules"]
            for f in files:
                if f.endswith(exts):
                    text.append(read(os.path.join(dirpath, f)))
    return set(re.findall(r"--[a-z][a-z0-9-]*", "\n".join(text))) | EXTERNAL_FLAGS


def check_flags(root, bin_dir):
    known = known_flags(root, bin_dir)
    bad = []
    for rel in READMES:
        path = os.path.join(root, rel)
        if not os.path.exists(path):
            continue
        # A family named with a star (`--export-max-*`) is a prefix.
        for flag in sorted(set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*[a-z0-9](?:-\*)?", read(path)))):
            if flag.endswith("-*"):
                if not any(k.startswith(flag[:-1]) for k in known):
                    bad.append(f"{rel}: no flag of ours begins {flag[:-1]}")
                continue
            if flag not in known:
                bad.append(f"{rel}: {flag} is in no program's --help nor any script of ours")
    return bad


PLACEHOLDER = re.compile(r"[*{}<>$~ ]|\b[A-Z]{2,}[A-Z0-9_]*\b|\.\.\.")
NOT_REPO = ("build/", "out/", "/", "http", "../", ".carry", "node_modules", "tests/e2e/node_modules", "$")


def path_candidates(text):
    for m in re.finditer(r"`([^`\n]+)`", text):
        yield m.group(1)
    for m in re.finditer(r"\]\(([^)\s]+)\)", text):
        yield m.group(1)


def looks_like_path(token):
    token = token.split("#")[0].split(":")[0].rstrip(".,;)")
    if not token or PLACEHOLDER.search(token) or token.startswith(NOT_REPO) or token.startswith("-"):
        return None
    if "/" not in token or "=" in token or "(" in token or token.startswith("."):
        return None
    first = token.split("/")[0]
    # A domain (docker.io/..., nvidia.com/gpu) or a test's output folder (e2e_out/) is not ours.
    if not re.fullmatch(r"[a-z_][a-z0-9_-]*", first) or first.endswith("_out") or token in EXTERNAL_PATHS:
        return None
    return token


def check_paths(root):
    roots = ["", "server", "render_core", "tools", "web_client", "tests", "tests/gpu", "docs"]
    bad = []
    for rel in READMES:
        path = os.path.join(root, rel)
        if not os.path.exists(path):
            continue
        here = os.path.dirname(rel)
        for token in sorted(set(filter(None, map(looks_like_path, path_candidates(read(path)))))):
            bases = [here] + roots
            if not any(os.path.exists(os.path.join(root, b, token)) for b in bases):
                bad.append(f"{rel}: `{token}` does not exist (looked in the repository, {here or '.'}/ and the "
                           "include roots)")
    return bad


def layout_rooms(root):
    """The rooms of README.md's Layout table under render_core/ and server/, top to bottom."""
    text = read(os.path.join(root, "README.md"))
    table = text[text.index("## Layout"):]
    rooms = []
    for m in re.finditer(r"^\| `([^`]+)`", table, re.M):
        name = m.group(1).rstrip("/")
        if name.startswith(("server", "render_core/")):
            rooms.append(name)
    return rooms


def room_of_file(rel, rooms):
    folder = os.path.dirname(rel)
    while folder:
        if folder in rooms:
            return folder
        folder = os.path.dirname(folder)
    return None


def room_of_include(inc, includer_room, root, rooms):
    if "/" not in inc:
        return includer_room
    for base in ["server", "render_core"]:
        if os.path.exists(os.path.join(root, base, inc)):
            r = room_of_file(os.path.join(base, inc), rooms)
            if r:
                return r
    return None  # proto, generated or third-party


def check_layering(root):
    rooms = layout_rooms(root)
    if "server" not in rooms or "render_core/base" not in rooms:
        return [f"README.md: the Layout table lists no server/ or render_core/base/ row (read {rooms})"]
    order = {r: i for i, r in enumerate(rooms)}
    bad = []
    files = subprocess.run(["git", "-C", root, "ls-files", "server", "render_core"], capture_output=True,
                           text=True).stdout.split()
    for rel in files:
        if not rel.endswith((".h", ".cpp", ".cu", ".cuh")):
            continue
        mine = room_of_file(rel, rooms)
        if not mine:
            continue
        for inc in re.findall(r'^\s*#\s*include\s+"([^"]+)"', read(os.path.join(root, rel)), re.M):
            theirs = room_of_include(inc, mine, root, rooms)
            if not theirs or theirs == mine or order[theirs] > order[mine]:
                continue
            if (mine, theirs) in LAYERING_EXCEPTIONS or (mine, "*") in LAYERING_EXCEPTIONS:
                continue
            bad.append(f"{rel}: includes \"{inc}\" ({theirs}/, above {mine}/ in README.md's Layout table)")
    return bad


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--source-dir", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
    ap.add_argument("--bin-dir", default="")
    ap.add_argument("--only", default="lines,flags,paths,layering")
    a = ap.parse_args()
    root = os.path.abspath(a.source_dir)
    checks = {
        "lines": lambda: check_lines(root),
        "flags": lambda: check_flags(root, a.bin_dir),
        "paths": lambda: check_paths(root),
        "layering": lambda: check_layering(root),
    }
    failed = 0
    for name in a.only.split(","):
        bad = checks[name]()
        print(f"{name}: {'ok' if not bad else str(len(bad)) + ' wrong'}")
        for b in bad:
            print("  " + b)
        failed += len(bad)
    if not a.bin_dir:
        print("flags: no --bin-dir, so no program's --help was read")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
