#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""`mpirun -n N sphles reference` gives the one-process reference bit for bit (docs/reference.md).

A 20^3 Taylor-Green reference (Re = 1600) computed four ways, compared byte for byte
(timeseries.csv, every spectrum and slice) and value for value (every dataset and attribute of
every checkpoint, with h5py; the files themselves differ only in HDF5's modification times):
  1. one process, two threads;
  2. 2 MPI ranks (10 z planes each);
  3. 3 MPI ranks (7, 7 and 6 planes: a rank with a shorter slab transposes through FFTW's
     larger arrays);
  4. 2 ranks to t = 0.25, continued on 3 ranks with --restart to the end.
Then SIGUSR1 to mpiexec stops a 2-rank reference with a checkpoint and exit code 1 (rank 0 hears
it and tells the others), and one process continues it to the same bits; and a 2D reference under
mpirun runs on rank 0 alone, equal to one process.
Usage: check_mpi_reference.py SPHLES MPIEXEC WORKDIR
"""
import filecmp
import os
import shutil
import signal
import subprocess
import sys
import time

import h5py
import numpy as np

SETTINGS = ["reference.points_per_side=20", "time.end=0.5", "reference.every=0.125",
            "checkpoint.every=0.25", "checkpoint.keep=10"]


def sets(settings):
    return [a for s in settings for a in ("--set", s)]


def run(command, env, expect=0):
    print("+", " ".join(command), flush=True)
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    if done.returncode != expect:
        sys.exit(f"command gave rc {done.returncode}, expected {expect}:\n{done.stdout}\n"
                 f"{done.stderr}")
    return done


def outputs(directory):
    """The files whose bytes must agree: the time series, spectra and slices."""
    files = ["timeseries.csv"]
    for sub in ("spectra", "slices"):
        files += [os.path.join(sub, n) for n in sorted(os.listdir(os.path.join(directory, sub)))]
    return files


def same_outputs(reference, other, label):
    files = outputs(reference)
    if files != outputs(other):
        sys.exit(f"{label}: other files: {outputs(other)} against {files}")
    for f in files:
        if not filecmp.cmp(os.path.join(reference, f), os.path.join(other, f), shallow=False):
            sys.exit(f"{label}: {f} differs from one process's")
    print(f"{label}: {len(files)} files the same bytes as one process's", flush=True)


def checkpoint_contents(path):
    with h5py.File(path, "r") as f:
        attributes = {k: (v.tobytes() if isinstance(v, np.ndarray) else v)
                      for k, v in f.attrs.items()}
        data = {k: f[k][...].view(np.uint64).tobytes() for k in f.keys()}
    return attributes, data


def same_checkpoints(reference, other, label, names=None):
    directory = os.path.join(reference, "checkpoints")
    names = names or sorted(os.listdir(directory))
    for n in names:
        a = checkpoint_contents(os.path.join(directory, n))
        b = checkpoint_contents(os.path.join(other, "checkpoints", n))
        if a != b:
            sys.exit(f"{label}: checkpoint {n} holds other values than one process's")
    print(f"{label}: checkpoints {names} hold one process's values bit for bit", flush=True)


def main():
    sphles, mpiexec, work = sys.argv[1:4]
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    env = dict(os.environ, OMP_NUM_THREADS="1", OMPI_ALLOW_RUN_AS_ROOT="1",
               OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    mpi = [mpiexec, "--oversubscribe", "-n"]
    base = [sphles, "reference", "tgv3d-re1600"]
    one = os.path.join(work, "one")
    run(base + sets(SETTINGS) + ["--threads", "2", "--out", one], env)
    if len(os.listdir(os.path.join(one, "checkpoints"))) != 2:
        sys.exit("one process: expected checkpoints at t = 0.25 and 0.5")

    for ranks in ("2", "3"):
        out = os.path.join(work, f"ranks{ranks}")
        done = run(mpi + [ranks] + base + sets(SETTINGS) + ["--out", out], env)
        if f"the grid spans {ranks} MPI ranks" not in done.stderr:
            sys.exit(f"{ranks} ranks: the run does not say it spans them:\n{done.stderr}")
        same_outputs(one, out, f"{ranks} ranks")
        same_checkpoints(one, out, f"{ranks} ranks")

    # Restart on another rank count: 2 ranks to t = 0.25, then 3 ranks to 0.5.
    resumed = os.path.join(work, "resumed")
    half = [s if not s.startswith("time.end") else "time.end=0.25" for s in SETTINGS]
    run(mpi + ["2"] + base + sets(half) + ["--out", resumed], env)
    run(mpi + ["3", sphles, "reference", "--restart", resumed, "--set", "time.end=0.5"], env)
    same_outputs(one, resumed, "2 ranks, then 3 ranks from the checkpoint")
    same_checkpoints(one, resumed, "2 ranks, then 3 ranks from the checkpoint",
                     [sorted(os.listdir(os.path.join(one, "checkpoints")))[-1]])

    # SIGUSR1 to mpiexec (it forwards the signal to every rank): the ranks stop together after
    # the step with a checkpoint; one process continues to one process's bits.
    stopped = os.path.join(work, "stopped")
    long = [s if not s.startswith("time.end") else "time.end=200" for s in SETTINGS]
    long += ["reference.every=1000", "checkpoint.every=1000"]
    command = mpi + ["2"] + base + sets(long) + ["--out", stopped]
    print("+", " ".join(command), flush=True)
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    series = os.path.join(stopped, "timeseries.csv")
    deadline = time.monotonic() + 120
    while not os.path.exists(series) or sum(1 for _ in open(series)) < 20:
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            sys.exit("SIGUSR1: the long reference did not get going:\n" + process.communicate()[1])
        time.sleep(0.2)
    process.send_signal(signal.SIGUSR1)
    _, err = process.communicate(timeout=300)
    if process.returncode != 1 or "stopped at" not in err:
        sys.exit(f"SIGUSR1: expected rc 1 and 'stopped at', got rc {process.returncode}:\n{err}")
    names = os.listdir(os.path.join(stopped, "checkpoints"))
    if len([n for n in names if n.endswith(".h5")]) != 1 or any(".tmp" in n for n in names):
        sys.exit(f"SIGUSR1: expected one checkpoint and no temporary file: {names}")
    with open(series) as f:
        t_stop = float(f.readlines()[-1].split(",")[0])
    straight = os.path.join(work, "straight")
    end = f"time.end={t_stop + 0.25!r}"
    run(base + sets(long + [end]) + ["--out", straight], env)
    run([sphles, "reference", "--restart", stopped, "--set", end], env)
    if not filecmp.cmp(os.path.join(straight, "timeseries.csv"), series, shallow=False):
        sys.exit("SIGUSR1: the continued reference's time series differs from one process's")
    print(f"SIGUSR1: stopped at t = {t_stop}, continued to one process's bits", flush=True)

    # 2D: rank 0 alone.
    flat = [sphles, "reference", "tgv2d", "--set", "reference.points_per_side=32", "--set",
            "time.end=0.2"]
    run(flat + ["--out", os.path.join(work, "flat1")], env)
    done = run(mpi + ["2"] + flat + ["--out", os.path.join(work, "flat2")], env)
    if "runs on rank 0 alone" not in done.stderr:
        sys.exit(f"2D: the run does not say it runs on rank 0 alone:\n{done.stderr}")
    same_outputs(os.path.join(work, "flat1"), os.path.join(work, "flat2"), "2D on 2 ranks")


if __name__ == "__main__":
    main()
