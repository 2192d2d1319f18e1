#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Every source file git tracks names its licence: `SPDX-License-Identifier: GPL-3.0-or-later`.

sphles is GPL-3.0-or-later (LICENSE): it links FFTW (GPL-2.0-or-later) and ships reference data
under GPL-3.0 (data/reference/README.md). The identifier sits in a comment on the first line,
or on the second after a `#!` line or `<!doctype html>`. Source files are the tracked *.cpp,
*.hpp, *.h, *.py, *.js, *.mjs, *.sh, *.cmake, *.css, *.html, CMakeLists.txt and executable
scripts (`#!`); data (JSON, CSV, reference files) carries no header, and neither does code kept
under a vendored directory (vendor/, node_modules/, third_party/), which keeps its own licence.

  scripts/check_spdx.py              # exit 1 naming the files without the line
  scripts/check_spdx.py --fix        # add the line where it is missing
  scripts/check_spdx.py --self-test  # the rules above on made-up files
"""
import argparse
import os
import re
import subprocess
import sys

LICENCE = "GPL-3.0-or-later"
TAG = "SPDX-License-Identifier: "
SUFFIXES = {".cpp", ".hpp", ".h", ".py", ".js", ".mjs", ".sh", ".cmake", ".css", ".html"}
VENDORED = {"vendor", "node_modules", "third_party", "thirdparty", "external"}
# Lines the identifier may follow: an interpreter line, an HTML doctype.
PRELUDE = re.compile(r"^(#!|<!doctype\s)", re.IGNORECASE)
# The first lines searched for the identifier (a prelude line and the identifier's own).
HEAD_LINES = 2
SKIP = 77  # CTest's SKIP_RETURN_CODE


def comment(path):
    """The header line in the comment syntax of the file's language."""
    name = os.path.basename(path)
    suffix = os.path.splitext(name)[1]
    if suffix in {".cpp", ".hpp", ".h", ".js", ".mjs"}:
        return f"// {TAG}{LICENCE}"
    if suffix == ".css":
        return f"/* {TAG}{LICENCE} */"
    if suffix == ".html":
        return f"<!-- {TAG}{LICENCE} -->"
    return f"# {TAG}{LICENCE}"  # Python, shell, CMake, other scripts


def is_source(path, executable, first_line):
    parts = path.split("/")
    if any(p in VENDORED for p in parts[:-1]):
        return False
    name = parts[-1]
    if name == "CMakeLists.txt" or os.path.splitext(name)[1] in SUFFIXES:
        return True
    return executable and first_line.startswith("#!")


def licence_in(text):
    """The identifier the file's first lines name, or None."""
    for line in text.splitlines()[:HEAD_LINES]:
        if TAG in line:
            return line.split(TAG, 1)[1].split()[0].rstrip("*/->").strip()
    return None


def with_header(path, text):
    lines = text.splitlines(keepends=True)
    at = 1 if lines and PRELUDE.match(lines[0]) else 0
    return "".join(lines[:at] + [comment(path) + "\n"] + lines[at:])


def tracked_files(root):
    """(path, executable) of every file git tracks under root; None outside a git checkout."""
    try:
        out = subprocess.run(["git", "-C", root, "ls-files", "-s", "-z"], check=True,
                             capture_output=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    files = []
    for entry in out.split(b"\0"):
        if entry:
            meta, path = entry.split(b"\t", 1)
            files.append((path.decode(), meta.split()[0] == b"100755"))
    return files


def read(path):
    with open(path, encoding="utf-8", errors="replace") as f:
        return f.read()


def self_test():
    failures = []

    def expect(what, got, want):
        if got != want:
            failures.append(f"{what}: got {got!r}, expected {want!r}")

    spdx = f"{TAG}{LICENCE}"
    expect("C++ with the line", licence_in(f"// {spdx}\n// What it is.\n#pragma once\n"), LICENCE)
    expect("C++ without it", licence_in("// What it is.\n#pragma once\n"), None)
    expect("line too far down", licence_in(f"// a\n// b\n// {spdx}\n"), None)
    expect("another licence", licence_in(f"// {TAG}MIT\n"), "MIT")
    expect("CSS comment", licence_in(f"/* {spdx} */\n"), LICENCE)
    expect("HTML comment", licence_in(f"<!doctype html>\n<!-- {spdx} -->\n"), LICENCE)
    expect("script after #!", licence_in(f"#!/usr/bin/env python3\n# {spdx}\n"), LICENCE)
    expect("Python fixed", with_header("a/b.py", '#!/usr/bin/env python3\n"""Doc."""\n'),
           f'#!/usr/bin/env python3\n# {spdx}\n"""Doc."""\n')
    expect("C++ fixed", with_header("sim/a.hpp", "// What it is.\n#pragma once\n"),
           f"// {spdx}\n// What it is.\n#pragma once\n")
    expect("HTML fixed", with_header("web/index.html", "<!doctype html>\n<html>\n"),
           f"<!doctype html>\n<!-- {spdx} -->\n<html>\n")
    expect("CMake fixed", with_header("x/CMakeLists.txt", "add_library(x)\n"),
           f"# {spdx}\nadd_library(x)\n")
    for path, executable, first, want in [
            ("sim/kernels.hpp", False, "//", True), ("CMakeLists.txt", False, "", True),
            ("cmake/EmbedFile.cmake", False, "#", True), ("web/style.css", False, "/*", True),
            (".ci/run", True, "#!/usr/bin/env bash", True), ("tests/e2e/x.mjs", False, "", True),
            ("web/vendor/uPlot.iife.min.js", False, "", False),
            ("tests/e2e/node_modules/a/index.js", False, "", False),
            ("scene/scene.schema.json", False, "{", False), ("data/reference/a.csv", False, "", False),
            ("tests/tsan.supp", False, "#", False), ("README.md", False, "#", False)]:
        expect(f"is_source({path})", is_source(path, executable, first), want)
    for f in failures:
        print("self-test:", f, file=sys.stderr)
    return 1 if failures else 0


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--root", default=os.path.join(os.path.dirname(__file__), ".."),
                        help="the repository (default: this script's)")
    parser.add_argument("--fix", action="store_true", help="add the line where it is missing")
    parser.add_argument("--self-test", action="store_true", help="check the rules themselves")
    args = parser.parse_args()
    if args.self_test:
        return self_test()
    files = tracked_files(args.root)
    if files is None:
        print(f"check_spdx: {args.root} is not a git checkout; nothing to check", file=sys.stderr)
        return SKIP
    missing, other, checked = [], [], 0
    for path, executable in files:
        full = os.path.join(args.root, path)
        if not os.path.isfile(full):
            continue  # deleted in the working tree, not yet committed
        text = read(full)
        if not is_source(path, executable, text.split("\n", 1)[0]):
            continue
        checked += 1
        found = licence_in(text)
        if found == LICENCE:
            continue
        if found is None and args.fix:
            with open(full, "w", encoding="utf-8") as f:
                f.write(with_header(path, text))
            print(f"added: {path}")
            continue
        (missing if found is None else other).append(f"{path}" + (f" ({found})" if found else ""))
    for path in missing:
        print(f"{path}: no '{TAG}{LICENCE}' in its first {HEAD_LINES} lines", file=sys.stderr)
    for path in other:
        print(f"{path}: names another licence; sphles is {LICENCE}", file=sys.stderr)
    if missing or other:
        print(f"check_spdx: {len(missing) + len(other)} of {checked} source files lack the "
              f"header (scripts/check_spdx.py --fix adds it)", file=sys.stderr)
        return 1
    print(f"check_spdx: all {checked} source files name {LICENCE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
