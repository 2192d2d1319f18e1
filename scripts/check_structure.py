#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The house rules a reader of the code relies on, checked over the tracked files.

  layering   a module includes only modules below it (ARCHITECTURE.md, "Layers"): MODULES
             below lists them bottom up; tests/, bench/ and app/ sit on top of everything
  cycles     no two files include each other, directly or through others (a header and its
             source file count as one: a.cpp including b.hpp while b.cpp includes a.hpp ties
             a and b together as much as two headers including each other)
  sizes      no source file over MAX_FILE_LINES lines and no C++ function over
             MAX_FUNCTION_LINES lines outside tests/ (functions found by universal-ctags);
             the files and functions that are over today are listed in
             scripts/structure_debt.txt with their size now, which they may not exceed, and a
             listed entry that has come under the limit must leave the list
  tags       no tracker reference ("issue 12") outside docs/journal/: a reader of the code has
             no tracker; a comment says why in its own words or cites SPEC.md or a paper
  format     every C++ file is as clang-format (.clang-format) writes it

  scripts/check_structure.py [--root DIR] [CHECK ...]   # exit 1 naming each violation
  scripts/check_structure.py --self-test                # the rules on made-up files

Exit 77 (CTest's skip code) outside a git checkout, where there is no list of tracked files.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile

from check_spdx import tracked_files  # the tracked files, as the licence check lists them

# Bottom up. A module may include itself and the modules listed before it, never one after it
# or beside it. tests/, bench/ and app/ are the top: they may include any module.
MODULES = ["logging", "net", "sim", "scene", "io", "analysis", "spectral", "render", "remote", "par",
           "launch", "control", "server"]
# Libraries a module must not include: the solver knows no document format (scene/ reads the
# scene's JSON into sim's plain data).
FORBIDDEN_LIBRARIES = {"sim": ["nlohmann/"]}
SYSTEM_INCLUDE = re.compile(r'^\s*#\s*include\s+<([^>]+)>', re.MULTILINE)
TOP = {"tests", "bench", "app"}
MAX_FILE_LINES = 600
MAX_FUNCTION_LINES = 120
CXX = (".cpp", ".hpp", ".h")
SIZED = CXX + (".js", ".mjs", ".py")
DEBT_FILE = "scripts/structure_debt.txt"
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.MULTILINE)
TAG = re.compile(r"\bissues?\s*#?\s*[0-9]+\b", re.IGNORECASE)
SKIP = 77


def module_of(path):
    top = path.split("/", 1)[0]
    return top if "/" in path else None


def resolve(including, target, files):
    """The tracked file an #include "target" in `including` names, or None (a system file)."""
    local = os.path.normpath(os.path.join(os.path.dirname(including), target))
    if local in files:
        return local
    return target if target in files else None


def include_graph(texts):
    files = set(texts)
    graph = {}
    for path, text in texts.items():
        if path.endswith(CXX):
            graph[path] = [t for t in (resolve(path, inc, files) for inc in INCLUDE.findall(text))
                           if t is not None]
    return graph


def check_layering(graph):
    rank = {m: i for i, m in enumerate(MODULES)}
    errors = []
    for path, targets in sorted(graph.items()):
        source = module_of(path)
        if source is None or source in TOP:
            continue
        for target in targets:
            dest = module_of(target)
            if dest is None or dest == source:
                continue
            if source not in rank or dest not in rank:
                unknown = source if source not in rank else dest
                errors.append(f"{path}: includes {target}, but module '{unknown}' has no layer "
                              f"(add it to MODULES in scripts/check_structure.py and to "
                              f"ARCHITECTURE.md)")
            elif rank[dest] >= rank[source]:
                errors.append(f"{path}: includes {target}; '{source}' may only include modules "
                              f"below it ({', '.join(MODULES[:rank[source]]) or 'none'})")
    return errors


def strongly_connected(graph):
    """Tarjan's strongly connected components of two or more nodes: the include cycles."""
    index, low, stack, on_stack, components = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        work = [(v, iter(graph.get(v, [])))]
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        while work:
            node, children = work[-1]
            advanced = False
            for w in children:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(graph.get(w, []))))
                    advanced = True
                    break
                if w in on_stack:
                    low[node] = min(low[node], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    component.append(w)
                    if w == node:
                        break
                if len(component) > 1:
                    components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(components)


def check_cycles(graph, debt):
    errors = []
    found = {f"cycle:{' <-> '.join(c)}": len(c) for c in strongly_connected(graph)}
    for key, size in sorted(found.items()):
        if key not in debt:
            errors.append(f"include {key[len('cycle:'):]}: these files include each other; "
                          f"move what both need into one of them or a third file")
    for key in sorted(k for k in debt if k.startswith("cycle:") and k not in found):
        errors.append(f"{key}: listed in {DEBT_FILE} but no longer a cycle; remove its line")
    return errors


def unit_graph(graph):
    """The include graph between units: a header and its source file (a.hpp, a.cpp) are one
    unit, so a.cpp including b.hpp while b.cpp includes a.hpp is a cycle too."""
    units = {}
    for path, targets in graph.items():
        source = os.path.splitext(path)[0]
        units.setdefault(source, set()).update(
            t for t in (os.path.splitext(t)[0] for t in targets) if t != source)
    return {u: sorted(t) for u, t in units.items()}


def functions(root, paths):
    """(path, name, lines) of every C++ function definition universal-ctags finds."""
    ctags = shutil.which("ctags-universal") or shutil.which("ctags")
    if ctags is None:
        raise SystemExit("check_structure: 'ctags' (universal-ctags) not found; "
                         "scripts/setup.sh installs it")
    out = subprocess.run([ctags, "-L", "-", "-x", "--kinds-c++=f", "--fields=+ne",
                          "--_xformat=%{line} %{end} %F %N"], cwd=root,
                         input="\n".join(paths), capture_output=True, text=True, check=True)
    found = []
    for line in out.stdout.splitlines():
        parts = line.split(" ", 3)
        if len(parts) == 4 and parts[1].isdigit():
            found.append((parts[2], parts[3], int(parts[1]) - int(parts[0]) + 1))
    return found


def read_debt(text):
    """{key: ceiling}: a key is a path, path:function, or cycle:a <-> b (its ceiling the
    number of units in it)."""
    debt = {}
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            key, ceiling = line.rsplit(None, 1) if not line.startswith("cycle:") else (
                line, line.count("<->") + 1)
            debt[key] = int(ceiling)
    return debt


def check_sizes(root, texts, debt):
    measured = {}
    for path, text in texts.items():
        if path.endswith(SIZED) and not path.startswith("tests/"):
            lines = text.count("\n")
            if lines > MAX_FILE_LINES:
                measured[path] = lines
    cxx = sorted(p for p in texts if p.endswith(CXX) and not p.startswith("tests/"))
    for path, name, lines in functions(root, cxx):
        if lines > MAX_FUNCTION_LINES:
            key = f"{path}:{name}"
            measured[key] = max(lines, measured.get(key, 0))
    errors = []
    for key, lines in sorted(measured.items()):
        limit = MAX_FUNCTION_LINES if ":" in key else MAX_FILE_LINES
        what = "function" if ":" in key else "file"
        if key not in debt:
            errors.append(f"{key}: {what} of {lines} lines, over {limit}; split it")
        elif lines > debt[key]:
            errors.append(f"{key}: {what} grew to {lines} lines ({DEBT_FILE} allows {debt[key]} "
                          f"until it is split under {limit}); split it rather than grow it")
    for key in sorted(k for k in set(debt) - set(measured) if not k.startswith("cycle:")):
        errors.append(f"{key}: listed in {DEBT_FILE} but no longer over the limit (or gone); "
                      f"remove its line")
    return errors


def check_tags(texts):
    errors = []
    for path, text in sorted(texts.items()):
        if path.startswith("docs/journal/") or path == DEBT_FILE or path.endswith(
                "check_structure.py"):
            continue
        for number, line in enumerate(text.splitlines(), 1):
            match = TAG.search(line)
            if match:
                errors.append(f"{path}:{number}: '{match.group(0)}' names a tracker issue; say "
                              f"what it means instead")
    return errors


def check_format(root, texts):
    fmt = shutil.which("clang-format")
    if fmt is None:
        raise SystemExit("check_structure: 'clang-format' not found; scripts/setup.sh installs it")
    paths = sorted(p for p in texts if p.endswith(CXX))
    out = subprocess.run([fmt, "--dry-run", "--Werror", *paths], cwd=root, capture_output=True,
                         text=True)
    if out.returncode == 0:
        return []
    files = sorted(set(re.findall(r"^([^\s:]+):\d+:\d+: (?:error|warning)", out.stderr,
                                  re.MULTILINE)))
    return [f"{p}: not clang-format clean (clang-format -i {p})" for p in files] or [
        out.stderr.strip()]


def check_libraries(texts):
    errors = []
    for path, text in sorted(texts.items()):
        forbidden = FORBIDDEN_LIBRARIES.get(module_of(path), [])
        for header in SYSTEM_INCLUDE.findall(text):
            if any(header.startswith(prefix) for prefix in forbidden):
                errors.append(f"{path}: includes <{header}>; {module_of(path)}/ uses no "
                              f"{header.split('/')[0]} (see scripts/check_structure.py)")
    return errors


CHECKS = ["layering", "cycles", "sizes", "tags", "format"]


def run(root, texts, checks):
    graph = include_graph(texts)
    debt = read_debt(texts.get(DEBT_FILE, ""))
    errors = []
    for check in checks:
        if check == "layering":
            errors += check_layering(graph) + check_libraries(texts)
        elif check == "cycles":
            errors += check_cycles(unit_graph(graph), debt)
        elif check == "sizes":
            errors += check_sizes(root, texts, debt)
        elif check == "tags":
            errors += check_tags(texts)
        elif check == "format":
            errors += check_format(root, texts)
    return errors


def tracked(root):
    """{path: text} of every tracked text file; None outside a git checkout."""
    files = tracked_files(root)
    if files is None:
        return None
    texts = {}
    for path, _ in files:
        if not os.path.isfile(os.path.join(root, path)):
            continue
        try:
            with open(os.path.join(root, path), encoding="utf-8") as f:
                texts[path] = f.read()
        except UnicodeDecodeError:
            continue  # binary data
    return texts


def self_test():
    body = "int f() {\n" + "  x();\n" * (MAX_FUNCTION_LINES + 5) + "}\n"
    cases = {
        "upward include": ({"sim/a.hpp": '#include "server/b.hpp"\n', "server/b.hpp": ""},
                           ["layering"], 1),
        "downward include": ({"server/b.hpp": '#include "sim/a.hpp"\n', "sim/a.hpp": ""},
                             ["layering"], 0),
        "include of a later module": ({"spectral/a.hpp": '#include "render/b.hpp"\n',
                                       "render/b.hpp": ""}, ["layering"], 1),
        "json in the solver": ({"sim/a.cpp": "#include <nlohmann/json.hpp>\n"}, ["layering"], 1),
        "json in the scene": ({"scene/a.cpp": "#include <nlohmann/json.hpp>\n"}, ["layering"], 0),
        "tests include anything": ({"tests/t.cpp": '#include "server/b.hpp"\n',
                                    "server/b.hpp": ""}, ["layering"], 0),
        "two files include each other": ({"io/a.hpp": '#include "io/b.hpp"\n',
                                          "io/b.hpp": '#include "a.hpp"\n'}, ["cycles"], 1),
        "two units include each other": ({"io/a.cpp": '#include "io/b.hpp"\n',
                                          "io/b.cpp": '#include "io/a.hpp"\n', "io/a.hpp": "",
                                          "io/b.hpp": ""}, ["cycles"], 1),
        "a listed cycle": ({"io/a.hpp": '#include "io/b.hpp"\n',
                            "io/b.hpp": '#include "a.hpp"\n',
                            DEBT_FILE: "cycle:io/a <-> io/b\n"}, ["cycles"], 0),
        "a listed cycle that is gone": ({"io/a.hpp": "", DEBT_FILE: "cycle:io/a <-> io/b\n"},
                                        ["cycles"], 1),
        "a chain is no cycle": ({"io/a.hpp": '#include "io/b.hpp"\n',
                                 "io/b.hpp": '#include "io/c.hpp"\n', "io/c.hpp": ""},
                                ["cycles"], 0),
        "long file": ({"sim/a.cpp": "//\n" * (MAX_FILE_LINES + 1)}, ["sizes"], 1),
        "long file in debt": ({"sim/a.cpp": "//\n" * (MAX_FILE_LINES + 1),
                               DEBT_FILE: f"sim/a.cpp {MAX_FILE_LINES + 1}\n"}, ["sizes"], 0),
        "debt grew": ({"sim/a.cpp": "//\n" * (MAX_FILE_LINES + 2),
                       DEBT_FILE: f"sim/a.cpp {MAX_FILE_LINES + 1}\n"}, ["sizes"], 1),
        "stale debt": ({"sim/a.cpp": "//\n", DEBT_FILE: "sim/a.cpp 700\n"}, ["sizes"], 1),
        "long function": ({"sim/a.cpp": body}, ["sizes"], 1),
        "long function in a test": ({"tests/a.cpp": body}, ["sizes"], 0),
        "tracker tag": ({"sim/a.cpp": "// the fix of issue 17\n"}, ["tags"], 1),
        "tag in the journal": ({"docs/journal/x.md": "issue 17\n"}, ["tags"], 0),
        "the word issues": ({"sim/a.cpp": "// this issues 3D requests\n"}, ["tags"], 0),
        "plain prose": ({"sim/a.cpp": "// a known issue of the method\n"}, ["tags"], 0),
    }
    failed = 0
    for name, (files, checks, expected) in cases.items():
        with tempfile.TemporaryDirectory() as root:
            for path, text in files.items():
                os.makedirs(os.path.dirname(os.path.join(root, path)), exist_ok=True)
                with open(os.path.join(root, path), "w") as f:
                    f.write(text)
            got = len(run(root, files, checks))
            if got != expected:
                print(f"self-test '{name}': {got} violations, expected {expected}")
                failed += 1
    print(f"check_structure self-test: {len(cases) - failed} of {len(cases)} cases pass")
    return 1 if failed else 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--root", default=os.path.join(os.path.dirname(__file__), ".."))
    parser.add_argument("--self-test", action="store_true")
    parser.add_argument("checks", nargs="*", metavar="CHECK", help=", ".join(CHECKS))
    args = parser.parse_args()
    unknown = [c for c in args.checks if c not in CHECKS]
    if unknown:
        parser.error(f"unknown check '{unknown[0]}': one of {', '.join(CHECKS)}")
    if args.self_test:
        return self_test()
    root = os.path.abspath(args.root)
    texts = tracked(root)
    if texts is None:
        print(f"check_structure: {root} is not a git checkout; nothing to check")
        return SKIP
    checks = args.checks or CHECKS
    errors = run(root, texts, checks)
    for e in errors:
        print(e)
    print(f"check_structure ({', '.join(checks)}): {len(errors)} violation(s) over "
          f"{len(texts)} tracked files")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
