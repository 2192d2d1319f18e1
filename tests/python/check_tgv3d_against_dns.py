#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""scripts/tgv3d_against_dns.py on run directories with known answers: the DNS itself (no
misfit, its peak), the DNS energy 10 % too high (a 10 % e_v misfit), a run that stopped before
t = 12 (no misfits) and a directory without a time series (exit 1, named). Usage:
check_tgv3d_against_dns.py SCRATCH_DIR"""
import pathlib
import shutil
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "tgv3d_against_dns.py"
DNS = ROOT / "data" / "reference" / "tgv_re5000_incompact3d_1280_dairay2017.dat"


def write_run(directory, scale, end):
    directory.mkdir(parents=True)
    with open(DNS, encoding="utf-8") as f, open(directory / "timeseries.csv", "w",
                                                encoding="utf-8") as out:
        out.write("t,step,e_v\n")
        for step, line in enumerate(l for l in f if not l.startswith("#") and l.strip()):
            t, e = (float(x) for x in line.split()[:2])
            if t <= end + 1e-9:
                out.write(f"{t!r},{step},{scale * e!r}\n")


def rows(*runs):
    result = subprocess.run([sys.executable, str(SCRIPT), *map(str, runs)], capture_output=True,
                            text=True, check=False)
    table = [[c.strip() for c in line.strip("|").split("|")]
             for line in result.stdout.splitlines()[2:]]
    return result.returncode, table, result.stderr


def main():
    scratch = pathlib.Path(sys.argv[1])
    shutil.rmtree(scratch, ignore_errors=True)
    write_run(scratch / "dns", 1.0, 12.5)
    write_run(scratch / "high", 1.1, 12.5)
    write_run(scratch / "short", 1.0, 5.0)
    (scratch / "empty").mkdir()
    failures = []

    status, table, _ = rows(scratch / "dns", scratch / "high", scratch / "short")
    if status != 0 or len(table) != 3:
        failures.append(f"three runs: exit {status}, {len(table)} rows")
    else:
        dns, high, short = table
        # Sampling the DNS every 0.1 and interpolating back: below 0.1 % in e_v, and the peak
        # of -dE/dt (0.01554 at 8.74 in the file) found at the sample next to it.
        if dns[1] != "0.0 %":
            failures.append(f"the DNS against itself: e_v misfit {dns[1]}, expected 0.0 %")
        if dns[3] not in ("0.0155 (8.7)", "0.0155 (8.8)"):
            failures.append(f"the DNS' peak: {dns[3]}, expected 0.0155 at 8.7 or 8.8")
        if high[1] != "10.0 %":
            failures.append(f"the DNS energy x 1.1: e_v misfit {high[1]}, expected 10.0 %")
        if high[4] != dns[4]:
            failures.append(f"e_v(1.5)/e_v(0) of a scaled energy: {high[4]} against {dns[4]}")
        if short[1] != "-" or short[2] != "-" or short[5] != "-":
            failures.append(f"a run that ended at t = 5: {short}, expected no misfits")

    status, table, stderr = rows(scratch / "empty")
    if status != 1 or table or "timeseries.csv" not in stderr:
        failures.append(f"no time series: exit {status}, rows {table}, stderr {stderr!r}")

    for f in failures:
        print("FAILED:", f)
    if not failures:
        print("tgv3d_against_dns: all checks passed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
