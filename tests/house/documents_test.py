#!/usr/bin/env python3
"""The documents hold by the code (issue 75; ctest house_documents, label house).

Checks, each failure printed with the file and the offending name:
  lines     RESULTS.md and tests/gpu/RESULTS.md have at most 400 lines each (the results page is
            today's numbers; what came before lives in docs/history/).
  flags     every --flag that README.md, the component READMEs, docs/DESIGN.md and RESULTS.md name is one some program
            of ours offers: in the --help of the programs in BIN_DIR, or in the text of the
            scripts and test drivers that take it (scripts/, tests/**/*.sh, tests/e2e/*.mjs),
            or one of the outside tools' flags listed below (EXTERNAL_FLAGS). A table row that
            gives a catgs-server flag's default (`| `--flag [VALUE]` | DEFAULT ...`) gives the
            default catgs-server --help shows (the option table, server/server_options.cpp).
  paths     every repository path they name (in `code` or as a link target) exists: relative to
            the repository, to the document's folder (`../` too, unless it leaves the
            repository) or to one of the include roots (server/, render_core/, tools/,
            web_client/, tests/). Build outputs, the data folder and names with placeholders
            (NAME, *, {a,b}, <x>) are not paths of the repository; a Markdown file's name is never
            a placeholder (`docs/NOPE.md` is checked).
            The documents: the READMEs, docs/DESIGN.md, the RESULTS pages and docs/history/.
  layering  inside render_core/ and server/ a room includes only rooms below it in README.md's
            "Layout" table, except the includes listed in LAYERING_EXCEPTIONS (each says why);
            a folder of sources there that the table does not list fails until it is placed.

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
# Whose paths are checked too, and of those whose flags (the others name removed flags as history).
DOCUMENTS = ["docs/DESIGN.md", "RESULTS.md", "tests/gpu/RESULTS.md", "tests/gpu/results/README.md"]
FLAG_DOCUMENTS = ["docs/DESIGN.md", "RESULTS.md"]


def documents(root):
    """Every document whose paths are checked: the READMEs, DOCUMENTS and docs/history/*.md."""
    history = os.path.join(root, "docs", "history")
    pages = sorted("docs/history/" + f for f in os.listdir(history) if f.endswith(".md")) if os.path.isdir(history) else []
    return READMES + DOCUMENTS + pages
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
EXTERNAL_PATHS = {"lib/roles/ws/ops-ws.c", "nvidia/cuda", "gsplat/experimental/render/kernels/cuda/csrc/gaussian_inference/"}
# Files scripts/setup_web.sh generates (git-ignored): a fresh clone has them only after it.
GENERATED_PATHS = {"web_client/viewer/catgs_stream.proto", "web_client/viewer/catgs_stream.json",
                   "viewer/catgs_stream.proto", "viewer/catgs_stream.json"}
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


def server_defaults(bin_dir):
    """{flag: the default catgs-server --help shows}, from each option's '(default X)'."""
    exe = os.path.join(bin_dir, "catgs-server") if bin_dir else ""
    if not exe or not os.path.exists(exe):
        return {}
    usage = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=30).stdout
    out = {}
    for entry in re.split(r"\n(?=  --)", usage):  # an option's line and its wrapped help
        flat = " ".join(entry.split())
        m = re.match(r"(--[a-z0-9-]+)", flat)
        d = re.findall(r"\(default ([^)]*)\)", flat)
        if m and d:
            out[m.group(1)] = d[-1]
    return out


TABLE_DEFAULT = re.compile(r"^\| *`(--[a-z0-9-]+)(?: [A-Za-z|]+)?` *\| *([^|]*?) *\|", re.M)


def check_flag_defaults(root, rel, text, defaults):
    bad = []
    for flag, cell in TABLE_DEFAULT.findall(text):
        if flag not in defaults or not cell:
            continue
        shown = cell.split()[0].strip("`")
        if shown != defaults[flag].split()[0]:
            bad.append(f"{rel}: {flag}'s default is {defaults[flag]!r} in catgs-server --help, the table says {cell!r}")
    return bad


def check_flags(root, bin_dir):
    known = known_flags(root, bin_dir)
    defaults = server_defaults(bin_dir)
    bad = []
    for rel in READMES + FLAG_DOCUMENTS:
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
        bad += check_flag_defaults(root, rel, read(path), defaults)
    return bad


PLACEHOLDER = re.compile(r"[*{}<>$~ ]|\.\.\.")
CAPS_WORD = re.compile(r"\b[A-Z]{2,}[A-Z0-9_]*\b")  # NAME, WxH: a placeholder, except in a .md name
NOT_REPO = ("build/", "out/", "/", "http", ".carry", "node_modules", "tests/e2e/node_modules", "$", "../shared/")


def path_candidates(text):
    """(token, the text around it): `code` spans and link targets."""
    for m in re.finditer(r"`([^`\n]+)`|\]\(([^)\s]+)\)", text):
        around = text[max(0, m.start() - 300):m.end() + 200]
        yield m.group(1) or m.group(2), around


def in_named_commit(root, token, around, bases):
    """Whether a path gone from the tree is one a commit named near it held (history's
    `commit 2214945 holds them`), or names a branch of the repository."""
    if subprocess.run(["git", "-C", root, "rev-parse", "--verify", "-q", token], capture_output=True).returncode == 0:
        return True
    for commit in set(re.findall(r"\b[0-9a-f]{7,40}\b", around)):
        known = subprocess.run(["git", "-C", root, "cat-file", "-e", commit + "^{commit}"], capture_output=True)
        if known.returncode != 0:
            shallow = subprocess.run(["git", "-C", root, "rev-parse", "--is-shallow-repository"], capture_output=True,
                                     text=True).stdout.strip() == "true"
            if shallow:
                return True  # a clone without the history cannot tell: not counted against the page
            continue  # a number or a word, not a commit
        for b in bases:
            spec = f"{commit}:{os.path.normpath(os.path.join(b, token))}"
            if subprocess.run(["git", "-C", root, "cat-file", "-e", spec], capture_output=True).returncode == 0:
                return True
    return False


def looks_like_path(token):
    token = token.split("#")[0].split(":")[0].rstrip(".,;)")
    if not token or PLACEHOLDER.search(token) or token.startswith(NOT_REPO) or token.startswith("-"):
        return None
    if CAPS_WORD.search(token) and not token.endswith(".md"):
        return None
    if "/" not in token or "=" in token or "(" in token or (token.startswith(".") and not token.startswith("../")):
        return None
    first = token.split("/")[0] if not token.startswith("../") else "up"
    # A domain (docker.io/..., nvidia.com/gpu) or a test's output folder (e2e_out/) is not ours.
    if not re.fullmatch(r"[a-z_][a-z0-9_-]*", first) or first.endswith("_out") or token in EXTERNAL_PATHS | GENERATED_PATHS:
        return None
    return token


def check_paths(root):
    roots = ["", "server", "render_core", "tools", "web_client", "tests", "tests/gpu", "docs", "tests/gpu/results",
             "tests/results"]
    # A results topic's own files are named from its folder (`bench60/` of speculation/).
    for top in ["tests/gpu/results", "tests/results"]:
        if os.path.isdir(os.path.join(root, top)):
            roots += [f"{top}/{d}" for d in sorted(os.listdir(os.path.join(root, top)))
                      if os.path.isdir(os.path.join(root, top, d))]
    bad = []
    for rel in documents(root):
        path = os.path.join(root, rel)
        if not os.path.exists(path):
            continue
        here = os.path.dirname(rel)
        seen = set()
        for raw, around in path_candidates(read(path)):
            token = looks_like_path(raw)
            if not token or token in seen:
                continue
            seen.add(token)
            if token.startswith("../"):
                # Up from the document's folder: checked there, unless it leaves the repository
                # (../shared, the data beside the clone).
                up = os.path.normpath(os.path.join(here, token))
                if up.startswith("..") or token.startswith("../shared/"):
                    continue
                if not os.path.exists(os.path.join(root, up)):
                    bad.append(f"{rel}: `{token}` does not exist ({up})")
                continue
            bases = [here] + roots
            if not any(os.path.exists(os.path.join(root, b, token)) for b in bases) and \
                    not in_named_commit(root, token, around, bases):
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
    """The room of a file: its folder, or the nearest folder above it that is a room; a folder
    directly under render_core/ or server/ that is not a room is no room (None)."""
    folder = os.path.dirname(rel)
    while folder:
        if folder in rooms:
            return folder
        if os.path.dirname(folder) in ("render_core", "server"):
            return None
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
    unplaced = set()
    for rel in files:
        if not rel.endswith((".h", ".cpp", ".cu", ".cuh")):
            continue
        mine = room_of_file(rel, rooms)
        if not mine:
            unplaced.add(os.path.dirname(rel))
            continue
        for inc in re.findall(r'^\s*#\s*include\s+"([^"]+)"', read(os.path.join(root, rel)), re.M):
            theirs = room_of_include(inc, mine, root, rooms)
            if not theirs or theirs == mine or order[theirs] > order[mine]:
                continue
            if (mine, theirs) in LAYERING_EXCEPTIONS or (mine, "*") in LAYERING_EXCEPTIONS:
                continue
            bad.append(f"{rel}: includes \"{inc}\" ({theirs}/, above {mine}/ in README.md's Layout table)")
    for folder in sorted(unplaced):
        bad.append(f"{folder}/: sources in a folder README.md's Layout table does not list (place it there)")
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
