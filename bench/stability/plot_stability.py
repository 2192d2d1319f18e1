#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Stability map from the CSV of build/bench/sphles_stability (docs/stability.md).

    python3 bench/stability/plot_stability.py [CSV] [--out-dir DIR]

Defaults: CSV = docs/stability.csv, DIR = docs/figures. Writes
  stability_map.png      one panel per swept parameter, cells coloured by classification
  stability_metrics.png  max rms density deviation vs max paired fraction, with the thresholds
Needs matplotlib (Debian: python3-matplotlib, installed by scripts/setup.sh).
"""
import argparse
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

CLASS_COLOURS = {
    "stable": "#4daf4a",
    "noisy": "#ffbf00",
    "paired": "#984ea3",
    "blown_up": "#e41a1c",
}
KERNELS = ["wendland_c2", "wendland_c4", "wendland_c6", "quintic_spline"]
# 1D sweeps: group -> (column holding the swept value, axis label)
STRIPS = [
    ("mach", "sound_speed", "c_s [m/s] (Ma = 1/c_s)"),
    ("p_ref", "reference_pressure", "p_ref [Pa]"),
    ("cfl", "cfl_acoustic", "acoustic CFL factor C_ac"),
    ("viscosity", "dynamic_viscosity", "η [Pa s]"),
    ("forcing", "forcing_amplitude", "Kolmogorov χ [m/s²]"),
]


def read_rows(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for key, value in r.items():
            try:
                r[key] = float(value)
            except (TypeError, ValueError):
                pass
    return rows


def cell_text(r):
    """Short figures for a cell: paired %, rms density deviation %, energy ratio."""
    lines = [
        f"pair {100 * r['max_paired_fraction']:.1f}%",
        f"rms {100 * r['max_rms_density_deviation']:.1f}%",
    ]
    if r["classification"] == "blown_up":
        lines.append(f"t={r['time_reached']:.3g}")
    elif r["energy_ratio"] > 0:
        lines.append(f"E/E* {r['energy_ratio']:.2f}")
    return "\n".join(lines)


def draw_kernel_grid(ax, rows):
    grid = [r for r in rows if r["group"] == "kernel"]
    ratios = sorted({r["diameter_over_spacing"] for r in grid})
    for r in grid:
        x = ratios.index(r["diameter_over_spacing"])
        y = KERNELS.index(r["kernel"])
        ax.add_patch(
            plt.Rectangle((x - 0.5, y - 0.5), 1, 1, color=CLASS_COLOURS[r["classification"]],
                          ec="white", lw=2))
        ax.text(x, y, cell_text(r), ha="center", va="center", fontsize=7)
    ax.set_xlim(-0.5, len(ratios) - 0.5)
    ax.set_ylim(-0.5, len(KERNELS) - 0.5)
    ax.set_xticks(range(len(ratios)), [f"{v:g}" for v in ratios])
    ax.set_yticks(range(len(KERNELS)), KERNELS)
    ax.set_xlabel("D_K / Δl")
    n = int(grid[0]["particles_per_side"]) if grid else 0
    ax.set_title(f"kernel × D_K/Δl (2D TGV {n}², t = 5)")


def draw_strip(ax, rows, group, column, label):
    strip = [r for r in rows if r["group"] == group]
    strip.sort(key=lambda r: r[column])
    for x, r in enumerate(strip):
        ax.add_patch(
            plt.Rectangle((x - 0.5, -0.5), 1, 1, color=CLASS_COLOURS[r["classification"]],
                          ec="white", lw=2))
        ax.text(x, 0, cell_text(r), ha="center", va="center", fontsize=6.5)
    ax.set_xlim(-0.5, max(len(strip), 1) - 0.5)
    ax.set_ylim(-0.5, 0.5)
    ax.set_xticks(range(len(strip)), [f"{r[column]:g}" for r in strip])
    ax.set_yticks([])
    ax.set_xlabel(label)
    if strip:
        end = strip[0]["end_time"]
        case = "Kolmogorov" if strip[0]["case"] == "kolmogorov2d" else "TGV"
        ax.set_title(f"{group} (2D {case} {int(strip[0]['particles_per_side'])}², t = {end:g})")


def draw_long(ax, rows):
    strip = [r for r in rows if r["group"] == "long"]
    for x, r in enumerate(strip):
        ax.add_patch(
            plt.Rectangle((x - 0.5, -0.5), 1, 1, color=CLASS_COLOURS[r["classification"]],
                          ec="white", lw=2))
        ax.text(x, 0, cell_text(r), ha="center", va="center", fontsize=6.5)
    ax.set_xlim(-0.5, max(len(strip), 1) - 0.5)
    ax.set_ylim(-0.5, 0.5)
    ax.set_xticks(range(len(strip)), [r["label"].replace(" t=", "\nt=") for r in strip],
                  fontsize=7)
    ax.set_yticks([])
    ax.set_title("long runs (2D TGV)")


def legend_handles():
    return [Patch(color=c, label=name) for name, c in CLASS_COLOURS.items()]


def plot_map(rows, path):
    fig = plt.figure(figsize=(13, 15))
    grid = fig.add_gridspec(len(STRIPS) + 3, 1, height_ratios=[4] + [1.1] * (len(STRIPS) + 1) +
                            [0.3])
    draw_kernel_grid(fig.add_subplot(grid[0]), rows)
    for k, (group, column, label) in enumerate(STRIPS):
        draw_strip(fig.add_subplot(grid[k + 1]), rows, group, column, label)
    draw_long(fig.add_subplot(grid[len(STRIPS) + 1]), rows)
    legend_ax = fig.add_subplot(grid[len(STRIPS) + 2])
    legend_ax.axis("off")
    legend_ax.legend(handles=legend_handles(), ncol=4, loc="center", frameon=False)
    fig.suptitle("sphles stability map: classification per configuration\n"
                 "(pair = max paired fraction, rms = max rms density deviation, "
                 "E/E* = final energy / analytic or laminar, t = blow-up time)", fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_metrics(rows, path, rms_threshold, pair_threshold):
    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    floor = 1e-4
    for name, colour in CLASS_COLOURS.items():
        sel = [r for r in rows if r["classification"] == name]
        ax.scatter([max(r["max_paired_fraction"], floor) for r in sel],
                   [r["max_rms_density_deviation"] for r in sel], c=colour, label=name,
                   edgecolors="k", linewidths=0.4, s=36)
    ax.axvline(pair_threshold, color="#984ea3", ls="--", lw=1)
    ax.axhline(rms_threshold, color="#ffbf00", ls="--", lw=1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"max paired fraction over the checks (0 drawn at {floor:g})")
    ax.set_ylabel("max rms |ρ/ρ_ref − 1| over the checks")
    ax.set_title("Health figures of every run and the classification thresholds\n"
                 "(blown-up runs show their last check before the stop)", fontsize=10)
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv", nargs="?", default="docs/stability.csv")
    parser.add_argument("--out-dir", default="docs/figures")
    parser.add_argument("--rms-threshold", type=float, default=0.03,
                        help="HealthThresholds::noisy_rms_density_deviation")
    parser.add_argument("--paired-threshold", type=float, default=0.01,
                        help="HealthThresholds::paired_fraction")
    args = parser.parse_args()
    rows = read_rows(args.csv)
    if not rows:
        sys.exit(f"{args.csv}: no rows")
    os.makedirs(args.out_dir, exist_ok=True)
    map_path = os.path.join(args.out_dir, "stability_map.png")
    metrics_path = os.path.join(args.out_dir, "stability_metrics.png")
    plot_map(rows, map_path)
    plot_metrics(rows, metrics_path, args.rms_threshold, args.paired_threshold)
    print(f"wrote {map_path} and {metrics_path} from {len(rows)} rows")


if __name__ == "__main__":
    main()
