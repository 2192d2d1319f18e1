#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Compares 3D Taylor-Green runs at Re = 5000 with the DNS of Dairay et al. (2017).

For each run directory (its timeseries.csv: columns t and e_v), prints one Markdown table row
with the measures of docs/accuracy.md, computed as bench/accuracy does:
  - e_v sampled every --sample time units (linear interpolation of timeseries.csv);
  - -de_v/dt by centred differences of those samples (one-sided at the ends), its largest value
    for t <= 12 and when it occurs;
  - the relative L2 misfit of e_v and of -de_v/dt on the DNS' times (every 0.02) in [0, 12],
    the samples interpolated linearly;
  - e_v(1.5) / e_v(0) and e_v(12).
A run that has not reached t = 12 gets no misfits ("-").

Usage: scripts/tgv3d_against_dns.py RUN_DIR [RUN_DIR ...] [--sample 0.1] [--dns FILE]
"""
import argparse
import csv
import math
import pathlib
import sys

END = 12.0
DEFAULT_DNS = (pathlib.Path(__file__).resolve().parent.parent / "data" / "reference" /
               "tgv_re5000_incompact3d_1280_dairay2017.dat")


def read_dns(path):
    """The DNS' times, energies and -dE/dt (columns 1-3), '#' lines skipped."""
    t, e, d = [], [], []
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            cols = [float(x) for x in line.split()]
            t.append(cols[0])
            e.append(cols[1])
            d.append(cols[2])
    return t, e, d


def read_run(run_dir):
    """t and e_v of a run's timeseries.csv, in time order, repeated times (a restart) dropped."""
    path = pathlib.Path(run_dir) / "timeseries.csv"
    t, e = [], []
    with open(path, newline="", encoding="utf-8") as f:
        for row in csv.DictReader(f):
            time, energy = float(row["t"]), float(row["e_v"])
            if t and time <= t[-1]:
                continue
            t.append(time)
            e.append(energy)
    if len(t) < 2:
        raise ValueError(f"{path}: fewer than two rows")
    return t, e


def interpolate(xs, ys, x):
    """Linear interpolation of (xs, ys) at x, xs ascending; the end values beyond them."""
    if x <= xs[0]:
        return ys[0]
    if x >= xs[-1]:
        return ys[-1]
    lo, hi = 0, len(xs) - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xs[mid] <= x:
            lo = mid
        else:
            hi = mid
    w = (x - xs[lo]) / (xs[hi] - xs[lo])
    return ys[lo] + w * (ys[hi] - ys[lo])


def measures(run_t, run_e, dns, sample):
    """The row's measures as a dict (misfits None when the run ends before t = 12)."""
    count = int(math.floor(run_t[-1] / sample + 1e-9)) + 1
    ts = [k * sample for k in range(count)]
    es = [interpolate(run_t, run_e, x) for x in ts]
    eps = []
    for k in range(count):
        lo, hi = max(k - 1, 0), min(k + 1, count - 1)
        eps.append(-(es[hi] - es[lo]) / (ts[hi] - ts[lo]) if hi > lo else 0.0)
    peak, peak_time = -1.0, float("nan")
    for x, d in zip(ts, eps):
        if x <= END + 1e-9 and d > peak:
            peak, peak_time = d, x
    out = {"peak": peak, "peak_time": peak_time,
           "start_loss": interpolate(run_t, run_e, 1.5) / run_e[0],
           "e_end": interpolate(run_t, run_e, END) if run_t[-1] >= END - 1e-9 else None,
           "energy_misfit": None, "dissipation_misfit": None}
    if run_t[-1] >= END - 1e-9:
        de = ne = dd = nd = 0.0
        for x, e, d in zip(*dns):
            if x > END + 1e-9:
                break
            se, sd = interpolate(ts, es, x), interpolate(ts, eps, x)
            de += (se - e) ** 2
            ne += e * e
            dd += (sd - d) ** 2
            nd += d * d
        out["energy_misfit"] = math.sqrt(de / ne)
        out["dissipation_misfit"] = math.sqrt(dd / nd)
    return out


def percent(x):
    return "-" if x is None else f"{100.0 * x:.1f} %"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run directories (each with timeseries.csv)")
    parser.add_argument("--sample", type=float, default=0.1,
                        help="sampling interval of e_v for -de_v/dt (default 0.1)")
    parser.add_argument("--dns", default=str(DEFAULT_DNS), help="the DNS file")
    args = parser.parse_args()
    if not args.sample > 0.0:
        parser.error(f"--sample must be positive, got {args.sample}")
    dns = read_dns(args.dns)
    print("| run | e_v misfit [0, 12] | -de_v/dt misfit | peak -de_v/dt (t) "
          "| e_v(1.5)/e_v(0) | e_v(12) |")
    print("|---|---|---|---|---|---|")
    status = 0
    for run in args.runs:
        try:
            m = measures(*read_run(run), dns, args.sample)
        except (OSError, KeyError, ValueError) as error:
            print(f"tgv3d_against_dns: {run}: {error}", file=sys.stderr)
            status = 1
            continue
        e_end = "-" if m["e_end"] is None else f"{m['e_end']:.4f}"
        print(f"| {run} | {percent(m['energy_misfit'])} | {percent(m['dissipation_misfit'])} "
              f"| {m['peak']:.4f} ({m['peak_time']:.1f}) | {m['start_loss']:.4f} | {e_end} |")
    return status


if __name__ == "__main__":
    sys.exit(main())
