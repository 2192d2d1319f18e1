#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Estimates against runs: `sphles estimate --time --json` of a scene beside the wall time and the
peak resident memory of `sphles run` of the same scene (GNU time), for a few cases with and
without analysis (docs/performance.md, "Whole runs"), with a packing cache of their own that
starts empty (so the estimate times each packing the run does).
Usage: estimates_vs_runs.py SPHLES WORKDIR [THREADS]
"""
import json
import os
import re
import shutil
import subprocess
import sys

PRODUCTS_ALL = ["energy", "spectrum", "vorticity", "slices", "sfs_stats", "particles", "fields"]
CASES = [
    ("24³, every product every 0.5, 3D view every 1",
     {"case": "tgv3d", "particles_per_side": 24, "fluid": {"dynamic_viscosity": 2e-4},
      "time": {"end": 2.0}, "analysis": {"every": 0.5, "products": PRODUCTS_ALL},
      "render": {"view3d": {"enabled": True, "every": 1.0}}}),
    ("24³, no analysis",
     {"case": "tgv3d", "particles_per_side": 24, "time": {"end": 2.0}}),
    ("32³, energy and spectrum every 0.25",
     {"case": "tgv3d", "particles_per_side": 32, "time": {"end": 2.0},
      "analysis": {"every": 0.25, "products": ["energy", "spectrum"]}}),
    ("48³, energy and spectrum every 0.5",
     {"case": "tgv3d", "particles_per_side": 48, "time": {"end": 1.0},
      "analysis": {"every": 0.5, "products": ["energy", "spectrum"]}}),
    ("64³, energy and spectrum every 0.25",
     {"case": "tgv3d", "particles_per_side": 64, "time": {"end": 0.5},
      "analysis": {"every": 0.25, "products": ["energy", "spectrum"]}}),
    ("256², slices and ω² frames every 0.1",
     {"case": "tgv2d", "particles_per_side": 256, "time": {"end": 0.5},
      "analysis": {"every": 0.1, "products": ["energy", "spectrum", "vorticity", "slices"]},
      "render": {"fields": ["omega2"]}}),
]


def main():
    sphles, work = sys.argv[1], sys.argv[2]
    threads = sys.argv[3] if len(sys.argv) > 3 else "2"
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    env = dict(os.environ, XDG_CACHE_HOME=os.path.join(work, "cache"))
    print("| run | estimated time (packing) | measured (packing) | ratio | estimated peak | "
          "measured peak RSS | ratio |")
    print("|---|---|---|---|---|---|---|")
    for k, (name, scene) in enumerate(CASES):
        path = os.path.join(work, f"case{k}.json")
        with open(path, "w") as f:
            json.dump(scene, f)
        e = json.loads(subprocess.run([sphles, "estimate", path, "--time", "--json", "--threads",
                                       threads], capture_output=True, text=True,
                                      check=True, env=env).stdout)
        out = os.path.join(work, f"run{k}")
        run = subprocess.run(["/usr/bin/time", "-f", "TIME %e %M", sphles, "run", path,
                              "--threads", threads, "--out", out],
                             capture_output=True, text=True, env=env)
        if run.returncode != 0:
            sys.exit(f"{name}: the run failed:\n{run.stderr}")
        wall, peak_kib = map(float, re.search(r"TIME (\S+) (\S+)", run.stderr).groups())
        packing = re.search(r"packing: .*\((\S+) s\)", run.stderr)
        packing_s = float(packing.group(1)) if packing else 0.0
        est_t = e["time"]["seconds_to_end"]
        est_packing = e["time"]["packing_seconds"]
        measured_t = wall
        est_m = e["process_peak_bytes"] / 2**20
        peak = peak_kib / 1024
        print(f"| {name} | {est_t:.2f} s ({est_packing:.1f} s) | {measured_t:.2f} s "
              f"({packing_s:.1f} s) | "
              f"{est_t / measured_t:.2f} | {est_m:.0f} MiB | {peak:.0f} MiB | {est_m / peak:.2f} |",
              flush=True)


if __name__ == "__main__":
    main()
