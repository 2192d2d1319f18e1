#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""`mpirun -n N sphles run` gives the one-process run bit for bit (docs/scaling.md).

Runs a small 2D Taylor-Green scene three ways and compares, with h5py, every particle array of
the final checkpoints (sorted by particle id: one process writes its own order, a distributed
run writes id order) and the time series:
  1. one process;
  2. 2 MPI ranks from the start, its particles made and packed by the ranks, each those of its
     half of the box (no rank holds them all; the packing cache they write, each its part, is
     one process's file byte for byte), with the energy and spectrum computed on the ranks and equal to
     one process's to 1e-12, and the particle products (the fitted vorticity's ⟨ω²⟩, the ω² and
     |τ_SFS| slices, the τ_SFS statistics) computed on the ranks and equal to one process's bit
     for bit, its particle snapshots written by both ranks into one file each and equal to
     one process's bit for bit, and its grid fields (velocity, omega2, tau_SFS over the whole
     analysis grid) computed on the ranks, their VTK files the same bytes as one process's (no
     particle gathered for the analysis);
     Its checkpoints are written by both ranks into one file each (parallel HDF5), none gathered;
  3. the 2-rank run's middle checkpoint continued on 3 ranks (`--restart`), read by the 3
     ranks, each a part of the file.
Then SIGUSR1 to mpiexec stops a 2-rank run as it stops one process: rank 0 finishes the step,
every rank helps write a checkpoint, the exit code is 1, and one process continues from it.
Usage: check_mpi_run.py SPHLES MPIEXEC WORKDIR
"""
import csv
import json
import os
import shutil
import signal
import subprocess
import sys

import h5py
import numpy as np
from compare_snapshots import same_bytes, same_grid_fields, same_particle_snapshots
from compare_spectra import compare_spectra

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "cli"))
from run_signals import stop_by_signal  # noqa: E402

SCENE_SETTINGS = [
    "particles_per_side=40", "time.end=0.2", "initial.mass=summation",
    "checkpoint.every=0.1", "checkpoint.keep=10",
    "analysis.every=0.05",
    'analysis.products=["energy","spectrum","vorticity","slices","sfs_stats","particles",'
    '"fields"]',
    'analysis.grid_fields=["velocity","omega2","tau_sfs"]',
    'analysis.particle_fields=["omega2","tau_sfs"]',
    "render.view3d.enabled=true", "render.view3d.max_points=1000",
    "render.view3d.width=320", "render.view3d.height=320",
]


def run(command, env):
    print("+", " ".join(command), flush=True)
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        sys.exit(f"command failed with rc {done.returncode}:\n{done.stdout}\n{done.stderr}")
    return done.stderr


def particles(checkpoint):
    with h5py.File(checkpoint, "r") as f:
        group = f["particles"]
        data = {name: group[name][()] for name in group}
    order = np.argsort(data["id"], kind="stable")
    return {name: values[order] for name, values in data.items()}


def checkpoints(directory):
    return sorted(os.path.join(directory, "checkpoints", n)
                  for n in os.listdir(os.path.join(directory, "checkpoints"))
                  if n.endswith(".h5"))


def same_final_state(reference, other, label):
    a = particles(checkpoints(reference)[-1])
    b = particles(checkpoints(other)[-1])
    if sorted(a) != sorted(b):
        sys.exit(f"{label}: checkpoint datasets differ: {sorted(a)} vs {sorted(b)}")
    differing = [n for n in a if not np.array_equal(a[n], b[n])]
    if differing:
        worst = {n: float(np.max(np.abs(a[n] - b[n]))) for n in differing}
        sys.exit(f"{label}: final particles differ from one process: {worst}")
    print(f"{label}: {len(a['id'])} particles, {len(a)} arrays equal bit for bit")


def same_particle_products(reference, other, label):
    """<omega^2>, nu <omega^2> and the tau_SFS maxima and means of every snapshot, every slice and
    every histogram file equal bit for bit."""
    columns = ("t", "mean_omega2", "dissipation_vorticity", "tau_sfs_max", "tau_sfs_mean")

    def values(run_dir):
        with open(os.path.join(run_dir, "stats", "snapshots.csv")) as f:
            return [tuple(r[c] for c in columns) for r in csv.DictReader(f)]
    a, b = values(reference), values(other)
    if not a or a != b:
        sys.exit(f"{label}: {columns} differ from one process:\n{a}\n{b}")
    if any(float(row[1]) <= 0.0 or float(row[3]) <= 0.0 for row in a):
        sys.exit(f"{label}: a mean_omega2 or tau_sfs_max is not positive: {a}")
    histograms = sorted(n for n in os.listdir(os.path.join(reference, "stats"))
                        if n != "snapshots.csv")
    if not histograms or histograms != sorted(n for n in os.listdir(os.path.join(other, "stats"))
                                              if n != "snapshots.csv"):
        sys.exit(f"{label}: the runs wrote different statistics files: {histograms}")
    same_bytes(reference, other, "stats", histograms, label)
    names = sorted(n for n in os.listdir(os.path.join(reference, "slices")) if n.endswith(".npy"))
    if len(names) != 2 * len(a):
        sys.exit(f"{label}: expected {2 * len(a)} omega2 and tau_sfs slices, found {names}")
    for name in names:
        x = np.load(os.path.join(reference, "slices", name))
        y = np.load(os.path.join(other, "slices", name))
        if x.shape != y.shape or not np.array_equal(x, y):
            sys.exit(f"{label}: slice {name} differs from one process")
    print(f"{label}: the particle products of {len(a)} snapshots computed on the ranks "
          f"({len(histograms)} histogram files, {len(names)} slices) equal one process's bit "
          "for bit")


def same_views(reference, other, label, count):
    """The 3D particle view's frames (every second particle by id of 1600: render.view3d.
    max_points = 1000), drawn from the points the ranks sent, the same bytes as one process's."""
    names = sorted(n for n in os.listdir(os.path.join(reference, "frames"))
                   if n.startswith("view3d_") and n.endswith(".png"))
    if len(names) != count or names != sorted(
            n for n in os.listdir(os.path.join(other, "frames"))
            if n.startswith("view3d_") and n.endswith(".png")):
        sys.exit(f"{label}: expected {count} view3d frames in both runs, found {names}")
    same_bytes(reference, other, "frames", names, label)
    print(f"{label}: {len(names)} 3D particle views from the ranks' points equal one process's "
          "byte for byte")


def main():
    sphles, mpiexec, work = sys.argv[1:4]
    scene = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scenes",
                         "tgv2d-validation.json")
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    env = dict(os.environ, OMP_NUM_THREADS="1", OMPI_ALLOW_RUN_AS_ROOT="1",
               OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMPI_MCA_mpi_yield_when_idle="1")
    settings = [a for s in SCENE_SETTINGS for a in ("--set", s)]
    one, two, three = (os.path.join(work, n) for n in ("one", "two", "three"))
    mpi = [mpiexec, "--oversubscribe", "--bind-to", "none", "-n"]

    # Each run packs its own particles (a cache of its own).
    caches = {n: os.path.join(work, "cache-" + n) for n in ("one", "two")}
    run([sphles, "run", scene, *settings, "--out", one, "--packing-cache", caches["one"]], env)
    log = run(mpi + ["2", sphles, "run", scene, *settings, "--out", two, "--log-level", "debug",
                     "--packing-cache", caches["two"]], env)
    if "spans 2 MPI ranks" not in log:
        sys.exit("the 2-rank run did not say it spans 2 ranks:\n" + log)
    if "particles made, packed and set up by the ranks" not in log or "converged" not in log:
        sys.exit("the 2-rank run did not pack its particles on the ranks:\n" + log[-2000:])
    packed = {n: sorted(os.listdir(c)) for n, c in caches.items()}
    if len(packed["one"]) != 1 or packed["one"] != packed["two"]:
        sys.exit(f"expected one packing cache file of the same name per run: {packed}")
    with open(os.path.join(caches["one"], packed["one"][0]), "rb") as f1, \
            open(os.path.join(caches["two"], packed["two"][0]), "rb") as f2:
        if f1.read() != f2.read():
            sys.exit("the packing cache written by 2 ranks differs from one process's")
    print("2 ranks: packed on the ranks, cache file equal to one process's")
    with open(os.path.join(two, "run.json")) as f:
        recorded = json.load(f).get("ranks")
    if recorded != 2:
        sys.exit(f"run.json of the 2-rank run records ranks {recorded}")
    # Computed on the ranks, no particle gathered for the analysis.
    where = log.count("spectrum and particle products computed on the ranks, "
                      "no particles gathered")
    if where != 5:
        sys.exit(f"expected 5 analysis snapshots computed on the ranks, the log says {where}:\n"
                 + log[-2000:])
    # Every checkpoint written by the ranks into one file, none gathered (read back below with
    # h5py and by the 3-rank restart).
    written = log.count("written by the ranks, no particles gathered")
    if written != len(checkpoints(two)):
        sys.exit(f"expected {len(checkpoints(two))} checkpoints written by the ranks, the log "
                 f"says {written}:\n" + log[-2000:])
    spectra, worst = compare_spectra(one, two, "2 ranks")
    print(f"2 ranks: {spectra} spectra computed on the ranks equal one process's to {worst:.2g}")
    same_particle_products(one, two, "2 ranks")
    same_particle_snapshots(one, two, "2 ranks", 5, ["omega2", "tau_sfs"])
    same_grid_fields(one, two, "2 ranks", 5)
    same_views(one, two, "2 ranks", 5)
    same_final_state(one, two, "2 ranks")
    with open(os.path.join(one, "timeseries.csv")) as f1, \
            open(os.path.join(two, "timeseries.csv")) as f2:
        if f1.read() != f2.read():
            sys.exit("2 ranks: timeseries.csv differs from one process")
    print("2 ranks: timeseries.csv equal")

    # The 2-rank run continued from its middle checkpoint on 3 ranks.
    shutil.copytree(two, three)
    files = checkpoints(three)
    if len(files) < 2:
        sys.exit(f"expected a middle checkpoint, found {files}")
    for f in files[1:]:
        os.remove(f)
    log = run(mpi + ["3", sphles, "run", "--restart", three], env)
    # The 3 ranks read the checkpoint, each its part; rank 0 reads the attributes only.
    if "(read by the ranks)" not in log:
        sys.exit("the 3-rank restart did not read its checkpoint on the ranks:\n" + log[-2000:])
    same_final_state(one, three, "restart of 2 ranks on 3")

    # mpirun forwards SIGUSR1 to every rank and does nothing else (on SIGTERM it kills the
    # ranks 1 s after forwarding it, whether their checkpoint is written or not).
    stop_by_signal(mpi + ["2"], sphles, scene, os.path.join(work, "stopped"), signal.SIGUSR1,
                   env)


if __name__ == "__main__":
    main()
