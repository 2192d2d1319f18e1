#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The omega^2 slices of several runs side by side (docs/analysis.md, "What the estimates show").

usage: plot_vorticity_estimates.py OUT.png LABEL=RUN_DIR [LABEL=RUN_DIR ...] [--times 0,2,5,8,10]

Each RUN_DIR is the output of `sphles run` with the slices product; the slices are read from
RUN_DIR/slices/omega2_t{t}.npy. One row per run, one column per time, each panel on its own
colour scale with its maximum in the title.
"""
import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out")
    parser.add_argument("runs", nargs="+", help="LABEL=RUN_DIR")
    parser.add_argument("--times", default="0,2,5,8,10")
    args = parser.parse_args()
    times = [float(t) for t in args.times.split(",")]
    runs = []
    for spec in args.runs:
        label, _, directory = spec.rpartition("=")
        if not directory:
            parser.error(f"'{spec}' is not LABEL=RUN_DIR")
        runs.append((label, pathlib.Path(directory)))
    fig, axes = plt.subplots(len(runs), len(times), figsize=(2.4 * len(times), 2.5 * len(runs)),
                             squeeze=False)
    for row, (label, directory) in enumerate(runs):
        for col, t in enumerate(times):
            path = directory / "slices" / f"omega2_t{t:.4f}.npy"
            if not path.exists():
                raise SystemExit(f"{path}: no omega2 slice at t = {t}")
            values = np.load(path)
            ax = axes[row][col]
            ax.imshow(values.T, origin="lower", cmap="inferno")
            ax.set_title(f"{label}, t = {t:g}\nmax {values.max():.2f}", fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(args.out, dpi=80)


if __name__ == "__main__":
    main()
