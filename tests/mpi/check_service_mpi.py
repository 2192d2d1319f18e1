#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The service runs a run's solver as an MPI job (docs/scaling.md, "From the service").

Against a real `sphles serve` on a real port, with a real launcher (mpiexec) and real ranks:
  1. a run created with "ranks": 2, its particles made and packed by the job's ranks, finishes
     with the final checkpoint and the time series of the same run with "ranks": 1 bit for bit (particles compared by id with h5py), its spectra
     (computed on the job's ranks) equal the 1-rank run's to 1e-12 and its slices and
     histograms (computed on the ranks too) bit for bit, its particle snapshots written by the
     job's ranks and equal to the 1-rank run's bit for bit, its grid fields computed on the
     ranks and written the same bytes, its checkpoints written by the job's
     ranks (none fetched), its spectra and slices are served, and its job ended (no worker
     process left);
  2. requests the server cannot honour are refused with 400 naming 'ranks';
  3. a rank killed during a 2-rank run fails the run cleanly: state "failed", a reason naming the
     launcher's report of the killed rank and the last valid checkpoint, the server still
     answering, no rank left behind; resuming the failed run launches a new job that continues
     from that checkpoint (read by the job's ranks), a live change reaches it, and stop ends it
     with a checkpoint.
Usage: check_service_mpi.py SPHLES MPIEXEC WORKDIR
"""
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request

import h5py
import numpy as np
from compare_snapshots import same_grid_fields, same_particle_snapshots
from compare_spectra import compare_spectra

SCENE = {"preset": "tgv2d",
         "patch": {"particles_per_side": 40,
                   "time": {"end": 0.2}, "checkpoint": {"every": 0.1, "keep": 10},
                   "analysis": {"every": 0.05,
                                "products": ["energy", "spectrum", "vorticity", "slices",
                                             "sfs_stats", "particles", "fields"],
                                "grid_fields": ["velocity", "omega2", "tau_sfs"],
                                "particle_fields": ["omega2", "tau_sfs"]},
                   "render": {"fields": ["omega2", "tau_sfs"],
                              "view3d": {"enabled": True, "max_points": 1000,
                                         "width": 320, "height": 320}}}}


def request(base, method, path, body=None):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(base + path, data=data, method=method,
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=60) as response:
            raw = response.read()
            return response.status, (json.loads(raw) if raw.startswith(b"{") or raw.startswith(b"[")
                                     else raw)
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read() or b"{}")


def wait_for(base, run_id, predicate, what, timeout=180):
    deadline = time.time() + timeout
    while time.time() < deadline:
        status, run = request(base, "GET", f"/api/runs/{run_id}")
        if status == 200 and predicate(run):
            return run
        time.sleep(0.2)
    sys.exit(f"run {run_id}: {what} not reached within {timeout} s; last: {run}")


def particles(checkpoint):
    with h5py.File(checkpoint, "r") as f:
        data = {name: f["particles"][name][()] for name in f["particles"]}
    order = np.argsort(data["id"], kind="stable")
    return {name: values[order] for name, values in data.items()}


def newest_checkpoint(run_dir):
    names = sorted(n for n in os.listdir(os.path.join(run_dir, "checkpoints")) if n.endswith(".h5"))
    return os.path.join(run_dir, "checkpoints", names[-1])


def compare_products(one, two):
    """The analysis products of a 2-rank run against one rank's (spectra to 1e-12 relative).
    Everything is computed on the job's ranks: the spectra by FFTW's MPI transform
    over 1 or 2 slabs, so they agree to round-off (and so do the spectral columns of
    snapshots.csv); the particle products (fitted vorticity, tau_SFS, their slices and
    histograms) gather their particles in an order set by positions and ids alone, so they are
    equal bit for bit."""
    spectra, worst_spectrum = compare_spectra(one, two, "2 ranks against 1")
    names = sorted(os.listdir(os.path.join(one, "stats")))
    if names != sorted(os.listdir(os.path.join(two, "stats"))) or not names:
        sys.exit("stats/: the runs wrote different files")
    for name in names:
        if name == "snapshots.csv":
            continue
        with open(os.path.join(one, "stats", name), "rb") as a, \
                open(os.path.join(two, "stats", name), "rb") as b:
            if a.read() != b.read():
                sys.exit(f"stats/{name} differs between 1 and 2 ranks")
    rows = []
    for run in (one, two):
        with open(os.path.join(run, "stats", "snapshots.csv")) as f:
            lines = f.read().splitlines()
        header = lines[0].split(",")
        keep = [k for k, name in enumerate(header) if name != "analysis_seconds"]
        rows.append(np.array([[float(line.split(",")[k]) for k in keep] for line in lines[1:]]))
    a, b = rows
    if a.shape != b.shape or not np.allclose(a, b, rtol=1e-12, atol=0, equal_nan=True):
        sys.exit(f"stats/snapshots.csv differs beyond 1e-12: max |a-b| "
                 f"{np.nanmax(np.abs(a - b)) if a.shape == b.shape else a.shape}")
    slices = sorted(n for n in os.listdir(os.path.join(one, "slices")) if n.endswith(".npy"))
    if not slices:
        sys.exit("no slices written")
    for name in slices:
        x, y = np.load(os.path.join(one, "slices", name)), np.load(os.path.join(two, "slices", name))
        if x.shape != y.shape or not np.array_equal(x, y):
            sys.exit(f"slices/{name} differs between 1 and 2 ranks")
    print(f"products: {spectra} spectra to {worst_spectrum:.2g} relative, the histograms byte "
          f"for byte, snapshots.csv to 1e-12, {len(slices)} slices bit for bit")


def command_lines():
    """(pid, argv as bytes) of every process this test may see, read from /proc."""
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                yield int(pid), f.read().rstrip(b"\0").split(b"\0")
        except OSError:
            continue


def worker_ranks(sphles):
    """pid -> rank of every `sphles worker` process of this test's program."""
    ranks = {}
    for pid, argv in command_lines():
        try:
            if len(argv) < 2 or os.path.realpath(argv[0].decode()) != sphles \
                    or argv[1] != b"worker":
                continue
            with open(f"/proc/{pid}/environ", "rb") as f:
                env = dict(e.split(b"=", 1) for e in f.read().split(b"\0") if b"=" in e)
            ranks[pid] = int(env.get(b"OMPI_COMM_WORLD_RANK", b"-1"))
        except (OSError, ValueError):
            continue
    return ranks


def wait_no_workers(sphles, timeout=30):
    deadline = time.time() + timeout
    while time.time() < deadline:
        if not worker_ranks(sphles):
            return
        time.sleep(0.2)
    sys.exit(f"worker processes left behind: {worker_ranks(sphles)}")


def main():
    sphles, mpiexec, work = os.path.realpath(sys.argv[1]), sys.argv[2], sys.argv[3]
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    env = dict(os.environ, OMP_NUM_THREADS="1", OMPI_ALLOW_RUN_AS_ROOT="1",
               OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMPI_MCA_mpi_yield_when_idle="1")
    data = os.path.join(work, "data")
    launcher = f"{mpiexec} --oversubscribe --bind-to none -n {{ranks}}"
    server = subprocess.Popen(
        [sphles, "serve", "--port", "0", "--data", data, "--threads", "1", "--max-running", "2",
         "--max-ranks", "3", "--launcher", launcher, "--log-level", "debug"],
        env=env, stdout=subprocess.PIPE, stderr=open(os.path.join(work, "serve.log"), "w"),
        text=True)
    try:
        line = server.stdout.readline()
        match = re.search(r"listening on (http://\S+?)/?$", line.strip())
        if not match:
            sys.exit(f"no 'listening on' line: {line!r}")
        base = match.group(1)

        # 1. Two ranks against one, bit for bit.
        ids = {}
        for ranks in (2, 1):
            status, run = request(base, "POST", "/api/runs",
                                  dict(SCENE, name=f"ranks{ranks}", ranks=ranks))
            if status != 201 or run.get("ranks") != ranks:
                sys.exit(f"create with ranks {ranks}: {status} {run}")
            ids[ranks] = run["id"]
        for ranks, run_id in ids.items():
            run = wait_for(base, run_id, lambda r: r["state"] in ("finished", "failed"), "the end")
            if run["state"] != "finished":
                sys.exit(f"the {ranks}-rank run {run_id} did not finish: {run['reason']}")
        dirs = {r: os.path.join(data, "runs", i) for r, i in ids.items()}
        # The 2-rank run's checkpoints are written by the job's ranks, none fetched (run.log
        # holds the run's lines at the server's log level).
        with open(os.path.join(dirs[2], "run.log")) as f:
            log = f.read()
        # Packed by the job's ranks (or read from the packing cache by them), none sent.
        if "particles made, packed and set up by the ranks" not in log:
            sys.exit("the 2-rank run's particles were not set up by the job's ranks:\n"
                     + log[-2000:])
        written = log.count("written by the ranks, no particles gathered")
        files = [n for n in os.listdir(os.path.join(dirs[2], "checkpoints")) if n.endswith(".h5")]
        if written != len(files):
            sys.exit(f"{written} checkpoints written by the job's ranks, expected {len(files)}")
        a, b = particles(newest_checkpoint(dirs[1])), particles(newest_checkpoint(dirs[2]))
        differing = [n for n in a if not np.array_equal(a[n], b[n])]
        if sorted(a) != sorted(b) or differing:
            sys.exit(f"2 ranks differ from 1: {differing or (sorted(a), sorted(b))}")
        with open(os.path.join(dirs[1], "timeseries.csv")) as f1, \
                open(os.path.join(dirs[2], "timeseries.csv")) as f2:
            if f1.read() != f2.read():
                sys.exit("the time series of 2 ranks differs from 1 rank's")
        compare_products(dirs[1], dirs[2])
        # The particle snapshots written by the job's ranks, none fetched.
        snapshots = len([n for n in os.listdir(os.path.join(dirs[1], "snapshots"))
                         if n.endswith(".h5")])
        same_particle_snapshots(dirs[1], dirs[2], "service, 2 ranks", snapshots,
                                ["omega2", "tau_sfs"], unlike=("scene",))
        same_grid_fields(dirs[1], dirs[2], "service, 2 ranks", snapshots)
        on_ranks = log.count("particle products computed on the ranks, no particles gathered")
        if snapshots < 2 or on_ranks != snapshots:
            sys.exit(f"{on_ranks} analysis snapshots of the 2-rank run gathered no particles, "
                     f"expected {snapshots}:\n" + log[-2000:])
        with open(os.path.join(dirs[2], "run.json")) as f:
            if json.load(f).get("ranks") != 2:
                sys.exit("run.json does not record ranks = 2")
        status, spectrum = request(base, "GET", f"/api/runs/{ids[2]}/spectrum")
        if status != 200 or not spectrum.get("energy"):
            sys.exit(f"the 2-rank run serves no spectrum: {status} {str(spectrum)[:200]}")
        status, image = request(base, "GET", f"/api/runs/{ids[2]}/images/omega2")
        if status != 200 or not image.startswith(b"\x89PNG"):
            sys.exit(f"the 2-rank run serves no omega2 image: {status}")
        # The 3D particle view, drawn from the points the job's ranks sent (every second
        # particle by id) at every analysis frame. (Its title names the run, so the two runs'
        # frames differ; mpi_run compares them with one process's byte for byte.)
        for run_dir in (dirs[1], dirs[2]):
            views = [n for n in os.listdir(os.path.join(run_dir, "frames"))
                     if n.startswith("view3d_") and n.endswith(".png")]
            if len(views) != snapshots:
                sys.exit(f"{run_dir}: expected {snapshots} view3d frames, found {views}")
        status, image = request(base, "GET", f"/api/runs/{ids[2]}/images/view3d")
        if status != 200 or not image.startswith(b"\x89PNG"):
            sys.exit(f"the 2-rank run serves no view3d image: {status}")
        with open(os.path.join(dirs[2], "job.log")) as f:
            if "rank 0 of 2 done" not in f.read():
                sys.exit("job.log does not show the job's rank 0 finishing")
        wait_no_workers(sphles)
        print(f"2 ranks = 1 rank bit for bit ({len(a['id'])} particles, {len(a)} arrays)")

        # 2. Refusals name the field.
        for body, why in ((dict(SCENE, ranks=0), ">= 1"), (dict(SCENE, ranks=4), "--max-ranks"),
                          (dict(SCENE, ranks="2"), ">= 1")):
            status, answer = request(base, "POST", "/api/runs", body)
            message = json.dumps(answer)
            if status != 400 or "ranks" not in message or why not in message:
                sys.exit(f"ranks={body['ranks']!r}: expected 400 naming 'ranks' ({why}), got "
                         f"{status} {message}")
        print("bad rank counts refused with 400")

        # 3. A killed rank fails the run cleanly; resume continues from the checkpoint.
        long_scene = {"preset": "tgv2d",
                      "patch": {"particles_per_side": 40, "packing": {"enabled": False},
                                "time": {"end": 1000.0}, "checkpoint": {"every": 0.5}}}
        status, run = request(base, "POST", "/api/runs", dict(long_scene, name="killed", ranks=2))
        if status != 201:
            sys.exit(f"create: {status} {run}")
        run_id = run["id"]
        run_dir = os.path.join(data, "runs", run_id)
        wait_for(base, run_id, lambda r: r["time"] > 1.2, "t > 1.2")
        victims = [pid for pid, rank in worker_ranks(sphles).items() if rank == 1]
        if len(victims) != 1:
            sys.exit(f"expected one rank-1 worker, found {worker_ranks(sphles)}")
        os.kill(victims[0], signal.SIGKILL)
        failed = wait_for(base, run_id, lambda r: r["state"] != "running", "a state change", 60)
        reason = failed["reason"]
        print(f"after the kill: {failed['state']}: {reason}")
        if failed["state"] != "failed" or "rank 1" not in reason or \
                "last valid checkpoint: checkpoints/ckpt_" not in reason:
            sys.exit("the run did not fail with a diagnosis naming rank 1 and the checkpoint")
        status, _ = request(base, "GET", "/api/runs")
        if status != 200:
            sys.exit("the server does not answer after the job died")
        wait_no_workers(sphles)
        named = re.search(r"checkpoints/(ckpt_\d+\.h5)", reason).group(1)
        with h5py.File(os.path.join(run_dir, "checkpoints", named), "r") as f:
            checkpoint_time = float(f.attrs["time"])

        status, run = request(base, "POST", f"/api/runs/{run_id}/resume")
        if status != 200 or run["state"] != "running":
            sys.exit(f"resume: {status} {run}")
        # The new job continues from the named checkpoint: its time series restarts there.
        wait_for(base, run_id, lambda r: r["state"] == "running" and
                 r["time"] > checkpoint_time + 0.2, "running past the checkpoint")
        # The new job's ranks read the checkpoint, each its part; nothing crossed the channel.
        # (The run's time can pass the mark above before the new job restored: wait for the line,
        # then for rows beyond the failed run's time, which only the new job writes.)
        deadline = time.time() + 60
        while True:
            with open(os.path.join(run_dir, "run.log")) as f:
                log = f.read()
            if "(read by the ranks)" in log or time.time() > deadline:
                break
            time.sleep(0.2)
        if f"{named} at t = " not in log.split("(read by the ranks)")[0][-400:]:
            sys.exit("the resumed job's ranks did not read the named checkpoint:\n" + log[-3000:])
        deadline = time.time() + 60
        while True:
            with open(os.path.join(run_dir, "timeseries.csv")) as f:
                times = [float(row.split(",")[0]) for row in f.read().splitlines()[1:]]
            # Past where the failed run had got to: rows the new job wrote.
            if (times and times[-1] > failed["time"] + 0.05) or time.time() > deadline:
                break
            time.sleep(0.2)
        if any(t1 <= t0 for t0, t1 in zip(times, times[1:])):
            sys.exit("the time series is not increasing after the resume")
        if not times or times[-1] <= failed["time"] + 0.05:
            sys.exit(f"the resumed job wrote no rows past t = {failed['time']}")
        status, changed = request(base, "PATCH", f"/api/runs/{run_id}/parameters",
                                  {"fluid": {"dynamic_viscosity": 0.02}})
        if status != 200:
            sys.exit(f"live change on the resumed job: {status} {changed}")
        time.sleep(1.0)
        status, run = request(base, "POST", f"/api/runs/{run_id}/stop")
        if status != 200 or run["state"] != "stopped":
            sys.exit(f"stop: {status} {run}")
        with open(os.path.join(run_dir, "scene.json")) as f:
            if json.load(f)["fluid"]["dynamic_viscosity"] != 0.02:
                sys.exit("the live change is not in scene.json")
        wait_no_workers(sphles)
        print(f"resumed from {named}, changed live, stopped at t = {run['time']:.3f}")
    finally:
        server.send_signal(signal.SIGTERM)
        try:
            server.wait(timeout=60)
        except subprocess.TimeoutExpired:
            server.kill()
    print("ok")


if __name__ == "__main__":
    main()
