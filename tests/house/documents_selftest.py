#!/usr/bin/env python3
"""documents_test.py against mutated copies (issue 93: a house test with no known hole).

Each case builds a small repository in a temporary folder (git init, a README.md with a Layout
table, docs/DESIGN.md, a few sources), breaks one thing the house test must catch, and runs the
check that must catch it; the unbroken repository passes every check. The holes each case closes:
  - a link to a Markdown file with an upper-case name (`docs/NOPE.md`), once read as a placeholder;
  - a `../` link from a component README (`../docs/gone.md`), once skipped;
  - a path and a flag named in docs/DESIGN.md, once not read;
  - a folder of sources under server/ or render_core/ the Layout table does not list, once taken
    for the `server` row (or skipped under render_core/);
  - a README table giving a server flag's default other than catgs-server --help's, once unread.

usage: documents_selftest.py   (exit 0 when every case fails as it must and the clean copy passes)
"""
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import documents_test as house  # noqa: E402

README = """# A repository

## Layout

| folder | what lives there |
|---|---|
| `server/session/` | sessions |
| `server/` | the server |
| `render_core/cpu/` | the CPU core |
| `render_core/base/` | what every room may use |

Design: [docs/DESIGN.md](docs/DESIGN.md); the server: [server/README.md](server/README.md).
"""
FILES = {
    "README.md": README,
    "docs/DESIGN.md": "The server (`server/server.cpp`) runs sessions (`server/session/session.h`).\n",
    "server/README.md": "Up: [the design](../docs/DESIGN.md). `catgs-server --port 8080`.\n\n"
                        "| flag | default | why |\n|---|---|---|\n| `--port N` | 8080 | the web's |\n",
    "server/server.cpp": '#include "session/session.h"\n',
    "server/session/session.h": '#pragma once\n#include "base/util.h"\n',
    "render_core/cpu/stage.cpp": '#include "base/util.h"\n',
    "render_core/base/util.h": "#pragma once\n",
}


def repository(folder, changes):
    """The small repository in `folder` with `changes` ({path: text, or None to leave it out})."""
    files = {**FILES, **changes}
    for rel, text in files.items():
        if text is None:
            continue
        os.makedirs(os.path.dirname(os.path.join(folder, rel)) or folder, exist_ok=True)
        with open(os.path.join(folder, rel), "w", encoding="utf-8") as f:
            f.write(text)
    subprocess.run(["git", "-C", folder, "init", "-q"], check=True)
    subprocess.run(["git", "-C", folder, "add", "-A"], check=True)
    return folder


def known_flags_here(root, bin_dir):
    return {"--port"}


def server_defaults_here(bin_dir):
    return {"--port": "8080"}


CASES = [
    ("a link to docs/NOPE.md", "paths", {"README.md": README + "See [the missing page](docs/NOPE.md).\n"}),
    ("a ../ link from a component README", "paths",
     {"server/README.md": FILES["server/README.md"] + "Also [gone](../docs/gone.md).\n"}),
    ("a path in docs/DESIGN.md", "paths", {"docs/DESIGN.md": FILES["docs/DESIGN.md"] + "See `server/nope.cpp`.\n"}),
    ("a flag in docs/DESIGN.md", "flags", {"docs/DESIGN.md": FILES["docs/DESIGN.md"] + "Run it with `--nope-flag`.\n"}),
    ("an unlisted server/newroom/ that includes session/", "layering",
     {"server/newroom/room.cpp": '#include "session/session.h"\n'}),
    ("an unlisted render_core/newroom/", "layering", {"render_core/newroom/room.h": '#include "base/util.h"\n'}),
    ("a flag's default in a README table that --help does not give", "flags",
     {"server/README.md": FILES["server/README.md"].replace("| 8080 |", "| 8081 |")}),
]


def run(root, check):
    house.known_flags = known_flags_here
    house.server_defaults = server_defaults_here
    return {
        "paths": lambda: house.check_paths(root),
        "flags": lambda: house.check_flags(root, ""),
        "layering": lambda: house.check_layering(root),
    }[check]()


def main():
    failures = 0
    with tempfile.TemporaryDirectory() as clean:
        repository(clean, {})
        for check in ["paths", "flags", "layering"]:
            bad = run(clean, check)
            print(f"{'ok  ' if not bad else 'FAIL'} the clean copy passes {check}" + (f": {bad}" if bad else ""))
            failures += bool(bad)
    for name, check, changes in CASES:
        with tempfile.TemporaryDirectory() as folder:
            bad = run(repository(folder, changes), check)
            print(f"{'ok  ' if bad else 'FAIL'} {check} catches {name}" + (f": {bad[0]}" if bad else ""))
            failures += not bad
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
