#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The offline run-directory reader (clients/python/sphles_run.py) on real run directories
written by `sphles run`: what it reads against the files themselves and the relations the
analysis guarantees (docs/analysis.md), and its errors.

Usage: check_run_reader.py SPHLES_BINARY WORK_DIR. Exits non-zero with the failed check."""

import csv
import os
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "clients", "python"))

import numpy as np  # noqa: E402
from sphles_run import RunDirectory  # noqa: E402

SIDE = 24
POINTS_PER_SPACING = 2
# Every product, analysed every 0.05 and checkpointed every 0.1: several frames of each kind,
# so that the nearest-time selection has neighbours to choose between.
FULL = ["--set", f"particles_per_side={SIDE}", "--set", "time.end=0.2",
        "--set", "packing.enabled=false", "--set", "analysis.every=0.05",
        "--set", f"analysis.grid_points_per_spacing={POINTS_PER_SPACING}",
        "--set", 'analysis.products=["energy","spectrum","vorticity","slices","sfs_stats",'
                 '"particles"]',
        "--set", 'analysis.slice.fields=["omega2","tau_sfs"]', "--set", "checkpoint.every=0.1"]
# Energy alone: no spectra, slices or particle snapshots.
MINIMAL = ["--set", "particles_per_side=16", "--set", "time.end=0.05",
           "--set", "packing.enabled=false", "--set", "analysis.every=0.05",
           "--set", 'analysis.products=["energy"]']


def check(condition, what):
    if not condition:
        sys.exit(f"check_run_reader: FAILED: {what}")
    print(f"ok: {what}")


def raises(call, kind, *needles):
    """The message of the ``kind`` exception that ``call`` raises; fails unless it names every
    one of ``needles``."""
    try:
        call()
    except kind as e:
        message = str(e)
        check(all(n in message for n in needles), f"{kind.__name__}: {message}")
        return message
    check(False, f"{kind.__name__} naming {needles}")


def make_run(binary, out, arguments):
    result = subprocess.run([binary, "run", "tgv2d", *arguments, "--out", out,
                             "--log-level", "warn"], capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit(f"check_run_reader: sphles run failed ({result.returncode}): {result.stderr}")


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def check_series(run, path):
    header, rows = read_csv(os.path.join(path, "timeseries.csv"))
    series = run.timeseries()
    check(list(series) == header, f"time-series columns are the CSV's: {header}")
    check(all(len(v) == len(rows) for v in series.values()) and len(rows) > 10,
          f"every column has the CSV's {len(rows)} rows")
    check(run.record["outputs"]["timeseries"]["count"] == len(rows), "run.json counts the rows")
    e_v0 = series["e_v"][0]
    check(series["t"][0] == 0 and e_v0 == float(rows[0][header.index("e_v")]),
          "e_v(0) is the CSV's first value, bit for bit")
    amplitude = run.scene["flow"]["velocity_amplitude"]
    check(abs(e_v0 - amplitude ** 2 / 4) < 1e-3, f"e_v(0) = {e_v0:.6f} = v0²/4 of the 2D TGV")
    check(np.array_equal(series["step"], np.arange(len(rows))), "steps 0, 1, ... as integers")
    units = run.units("timeseries.csv")
    check(list(units) == header and units["e_v"] == "m^2/s^2" and units["t"] == "s",
          f"units.csv gives every time-series column its unit: {units}")
    spectrum_units = run.units("spectra/E_t0.0500.csv")
    check(spectrum_units["k"] == "1/m" and spectrum_units["E"] == "m^3/s^2",
          "and a spectrum file's, matched by its time pattern")
    frames = run.analysis()
    check(frames["e_v"][0] == e_v0 and len(frames["t"]) == 5,
          "stats/snapshots.csv: 5 frames, its e_v(0) the time series'")


def check_spectra(run, path):
    times = run.spectrum_times()
    check(np.allclose(times, [0, 0.05, 0.1, 0.15, 0.2]), f"spectrum times {times}")
    frames = run.analysis()
    for i, t in enumerate(times):
        spectrum = run.spectrum(t, columns=True)
        total = spectrum["E"].sum() * spectrum["delta_k"]
        # Σ E Δk is ½⟨|u'|²⟩ of the gridded velocity to round-off (docs/analysis.md, Methods).
        check(abs(total - frames["e_v_grid"][i]) <= 1e-12 * frames["e_v_grid"][i],
              f"t = {t:g}: Σ E Δk = {total:.15f} = e_v_grid {frames['e_v_grid'][i]:.15f}")
    k, energy = run.spectrum()
    latest = np.loadtxt(os.path.join(path, "spectra", "E_t0.2000.csv"), delimiter=",",
                        skiprows=1)
    check(np.array_equal(k, latest[:, 0]) and np.array_equal(energy, latest[:, 1]),
          "spectrum() is the latest file")
    _, below = run.spectrum(0.074)
    _, above = run.spectrum(0.076)
    for name, got in (("E_t0.0500.csv", below), ("E_t0.1000.csv", above)):
        expected = np.loadtxt(os.path.join(path, "spectra", name), delimiter=",", skiprows=1)
        check(np.array_equal(got, expected[:, 1]), f"the spectrum nearest to the time is {name}")


def check_slices(run, path):
    check(run.slice_fields() == ["omega2", "tau_sfs"], "slice fields omega2, tau_sfs")
    side = POINTS_PER_SPACING * SIDE
    latest = run.slice("omega2")
    check(latest.shape == (side, side) and latest.dtype == np.float64,
          f"the ω² slice is {side} × {side} (grid_points_per_spacing × particles_per_side)")
    check(np.array_equal(latest, np.load(os.path.join(path, "slices", "omega2_t0.2000.npy"))),
          "slice() is the latest .npy")
    nearest = run.slice("tau_sfs", t=0.11)
    check(np.array_equal(nearest, np.load(os.path.join(path, "slices", "tau_sfs_t0.1000.npy"))),
          "the τ_SFS slice nearest to t = 0.11 is t = 0.1's")
    index = run.slices_index()
    check(latest.max() == index["max"][index["field"] == "omega2"][-1],
          "the slice's maximum is the index's")


def check_particles(run, path):
    snapshot = run.snapshot(t=0.12)
    check(snapshot.time == 0.1 and snapshot.path.endswith("particles_t0.1000.h5"),
          "the snapshot nearest to t = 0.12 is t = 0.1's")
    check(snapshot["position"].shape == (SIDE * SIDE, 3)
          and np.array_equal(snapshot["id"], np.arange(SIDE * SIDE)),
          "snapshot: positions (N, 3), row k is particle k")
    names = run.checkpoints()
    check(names == ["ckpt_0000000012.h5", "ckpt_0000000024.h5"],
          f"checkpoints at t = 0.1 and the end, oldest first: {names}")
    newest = run.checkpoint()
    check(newest.path.endswith(names[-1]) and newest.time == 0.2 == run.record["time"],
          "checkpoint() is the newest, at the run's end time")
    count = len(newest["velocity_x"])
    check(count == SIDE * SIDE == newest.attrs["num_particles"],
          f"the checkpoint holds particles_per_side² = {count} particles")
    first = run.checkpoint(names[0])
    check(first.step < newest.step and sorted(first["id"]) == list(range(count)),
          "an older checkpoint by name, every particle id once")


def check_errors(binary, work, run, path):
    missing = os.path.join(work, "no-such-run")
    raises(lambda: RunDirectory(missing), FileNotFoundError, missing)
    raises(lambda: RunDirectory(work), FileNotFoundError, os.path.join(work, "run.json"))
    raises(lambda: run.spectrum(0.5), ValueError, "spectra/index.csv", "0.5", "[0, 0.2]")
    raises(lambda: run.slice("omega2", t=-0.1), ValueError, "slices/index.csv", "outside")
    raises(lambda: run.slice("nu_t"), FileNotFoundError, "slices/index.csv", "nu_t")
    raises(lambda: run.checkpoint("ckpt_0000009999.h5"), FileNotFoundError,
           "ckpt_0000009999.h5", "no such checkpoint")

    minimal = os.path.join(work, "minimal")
    make_run(binary, minimal, MINIMAL)
    bare = RunDirectory(minimal)
    check(len(bare.analysis()["t"]) == 2, "an energy-only run has its statistics")
    raises(bare.spectrum, FileNotFoundError, os.path.join(minimal, "spectra", "index.csv"),
           "spectrum")
    raises(lambda: bare.slice("omega2"), FileNotFoundError,
           os.path.join(minimal, "slices", "index.csv"), "slices")
    raises(bare.snapshot, FileNotFoundError, os.path.join(minimal, "snapshots", "index.csv"),
           "particles")
    os.remove(os.path.join(path, "spectra", "E_t0.1000.csv"))
    raises(lambda: run.spectrum(0.1), FileNotFoundError, "E_t0.1000.csv")


def main():
    binary, work = sys.argv[1], os.path.abspath(sys.argv[2])
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    path = os.path.join(work, "tgv2d")
    make_run(binary, path, FULL)
    run = RunDirectory(path)
    check(run.record["state"] == "finished", "run.json: finished")
    check_series(run, path)
    check_spectra(run, path)
    check_slices(run, path)
    check_particles(run, path)
    check_errors(binary, work, run, path)
    print("check_run_reader: all checks passed")


if __name__ == "__main__":
    main()
