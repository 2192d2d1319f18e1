# SPDX-License-Identifier: GPL-3.0-or-later
"""What the reader checks share: a failure list, the CSV index reader, the final report."""
import sys

failures = []


def check(ok, what):
    if not ok:
        failures.append(what)


def index_rows(path):
    """The rows of a sphles CSV index as dicts by header name."""
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    return [dict(zip(header, line.split(","))) for line in lines[1:]]


def finish():
    for f in failures:
        print("FAIL:", f)
    print(f"{len(failures)} failures")
    sys.exit(1 if failures else 0)
