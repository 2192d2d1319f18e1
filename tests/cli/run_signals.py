#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""A signal stops `sphles run` with a checkpoint that continues (app/run_command.cpp).

For each of SIGINT, SIGTERM and SIGUSR1, a long 2D Taylor-Green run of one process is signalled
once it has written 20 rows of its time series; it must exit 1, say "stopped at" and which
signal stopped it, leave a complete checkpoint (no temporary file beside it) and continue from
that checkpoint with `--restart`. tests/mpi/check_mpi_run.py uses `stop_by_signal` for a 2-rank
run stopped through mpiexec. A run with analysis and rendered frames interrupted by SIGINT
writes the products and frames of every analysis time it reached (none is dropped), and its
restart writes the rest: every analysis time once. A restart from a checkpoint older than the
run's last outputs (what a crash leaves) writes the later times again, each once.
Usage: run_signals.py SPHLES SCENE WORKDIR
"""
import csv
import os
import shutil
import signal
import subprocess
import sys
import time

LONG_RUN = ["particles_per_side=40", "time.end=1000", "packing.enabled=false"]


def rows(path):
    try:
        with open(path) as f:
            return sum(1 for _ in f) - 1
    except FileNotFoundError:
        return 0


def stop_by_signal(launch, sphles, scene, out, signum, env):
    """Starts `launch + [sphles, "run", scene, ...]` into `out`, sends `signum` to the launched
    process (sphles, or mpiexec) once the run is going, checks the stop and continues the run
    from its checkpoint with one process. Returns the time the run stopped at."""
    name = signal.Signals(signum).name
    command = launch + [sphles, "run", scene, *[a for s in LONG_RUN for a in ("--set", s)],
                        "--out", out]
    print("+", " ".join(command), flush=True)
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while rows(os.path.join(out, "timeseries.csv")) < 20:
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            sys.exit(f"{name}: the long run did not get going:\n" + process.communicate()[1])
        time.sleep(0.2)
    process.send_signal(signum)
    _, err = process.communicate(timeout=300)
    expected = f"interrupted by signal {int(signum)}"
    if process.returncode != 1 or "stopped at" not in err or expected not in err:
        sys.exit(f"{name}: expected rc 1, 'stopped at' and '{expected}', got rc "
                 f"{process.returncode}:\n{err}")
    names = sorted(os.listdir(os.path.join(out, "checkpoints")))
    files = [n for n in names if n.endswith(".h5")]
    if not files:
        sys.exit(f"{name}: no checkpoint written: {names}")
    if any(".tmp" in n for n in names):
        sys.exit(f"{name}: a temporary checkpoint file was left: {names}")
    with open(os.path.join(out, "timeseries.csv")) as f:
        t_stop = float(list(csv.DictReader(f))[-1]["t"])
    if not 0 < t_stop < 1000:
        sys.exit(f"{name}: the time series ends at t = {t_stop}")
    # One process continues a little from the checkpoint.
    more = [sphles, "run", "--restart", out, "--set", f"time.end={t_stop + 0.02}"]
    print("+", " ".join(more), flush=True)
    done = subprocess.run(more, env=env, capture_output=True, text=True, timeout=300)
    if done.returncode != 0:
        sys.exit(f"{name}: the restart failed with rc {done.returncode}:\n{done.stderr}")
    print(f"{name}: stopped at t = {t_stop} with {files[-1]}; one process continued from it",
          flush=True)
    return t_stop


def analysis_times(path, column):
    with open(path) as f:
        return [float(row[column]) for row in csv.DictReader(f)]


def outputs_across_interrupt(sphles, out, env):
    """SIGINT, then --restart: every analysis time has its spectrum and its frames, once."""
    every = 0.01
    command = [sphles, "run", "tgv2d", "--threads", "1", "--out", out,
               "--set", "particles_per_side=40", "--set", "time.end=1000",
               "--set", "packing.enabled=false",
               "--set", f'analysis={{"every":{every},"products":["energy","spectrum","vorticity","slices"]}}',
               "--set", 'render={"fields":["omega2"],"width":1600,"height":800}']
    print("+", " ".join(command), flush=True)
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    spectra = os.path.join(out, "spectra", "index.csv")
    deadline = time.monotonic() + 120
    while rows(spectra) < 10:
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            sys.exit("the analysed run did not get going:\n" + process.communicate()[1])
        time.sleep(0.1)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=300)
    if process.returncode != 1 or " 0 dropped" not in err:
        sys.exit(f"interrupted analysed run: rc {process.returncode}, expected 0 dropped:\n{err}")
    with open(os.path.join(out, "timeseries.csv")) as f:
        t_stop = float(list(csv.DictReader(f))[-1]["t"])
    reached = int(t_stop / every + 1e-9) + 1
    expected = [k * every for k in range(reached)]

    def check(t_end, what):
        got = analysis_times(spectra, "t")
        want = [k * every for k in range(int(t_end / every + 1e-9) + 1)]
        if len(got) != len(want) or any(abs(a - b) > 1e-9 for a, b in zip(got, want)):
            sys.exit(f"{what}: spectra at {got[-5:]} ({len(got)}), expected {len(want)} "
                     f"times up to {want[-1]}")
        frames = analysis_times(os.path.join(out, "frames", "index.csv"), "time")
        for field_times in (frames[0::2], frames[1::2]):
            if len(field_times) != len(want):
                sys.exit(f"{what}: {len(frames)} frames for {len(want)} analysis times")

    check(expected[-1], f"stopped at t = {t_stop}")
    end = t_stop + 3 * every
    done = subprocess.run([sphles, "run", "--restart", out, "--set", f"time.end={end}"], env=env,
                          capture_output=True, text=True, timeout=300)
    if done.returncode != 0:
        sys.exit(f"the restart of the analysed run failed:\n{done.stderr}")
    check(end, "after the restart")
    print(f"interrupted at t = {t_stop}: {reached} analysis times with spectra and frames; "
          f"the restart added the rest, each once", flush=True)


def outputs_after_a_crash(sphles, out, env):
    """A crash after a checkpoint leaves the outputs of later times; the restart from that
    checkpoint writes them again, and every index still lists each analysis time once."""
    every = 0.01
    command = [sphles, "run", "tgv2d", "--threads", "1", "--out", out,
               "--set", "particles_per_side=24", "--set", "time.end=0.1",
               "--set", "packing.enabled=false", "--set", "checkpoint.every=0.05",
               "--set", f'analysis={{"every":{every},'
               '"products":["energy","spectrum","vorticity","slices"]}']
    print("+", " ".join(command), flush=True)
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    if done.returncode != 0:
        sys.exit(f"the run to be restarted failed:\n{done.stderr}")
    indices = ["timeseries.csv", "spectra/index.csv", "stats/snapshots.csv", "slices/index.csv"]

    def contents():
        """Every index's rows, without the wall time the analysis took."""
        result = {}
        for name in indices:
            with open(os.path.join(out, name)) as f:
                result[name] = [{k: v for k, v in row.items() if k != "analysis_seconds"}
                                for row in csv.DictReader(f)]
        return result

    before = contents()
    directory = os.path.join(out, "checkpoints")
    checkpoints = sorted(f for f in os.listdir(directory) if f.endswith(".h5"))
    if len(checkpoints) < 2:
        sys.exit(f"expected a checkpoint at t = 0.05 and one at the end, got {checkpoints}")
    # The run as a crash at t = 0.1 would leave it, continued from the older checkpoint.
    older = os.path.join(directory, checkpoints[0])
    done = subprocess.run([sphles, "run", "--restart", older], env=env, capture_output=True,
                          text=True, timeout=300)
    if done.returncode != 0:
        sys.exit(f"the restart from {checkpoints[0]} failed:\n{done.stderr}")
    after = contents()
    for name in indices:
        if after[name] != before[name]:
            sys.exit(f"{name} after the restart from {checkpoints[0]}: "
                     f"{[r['t'] for r in after[name]]}, expected {[r['t'] for r in before[name]]}")
    times = analysis_times(os.path.join(out, "spectra", "index.csv"), "t")
    if len(times) != 11 or len(set(times)) != 11:
        sys.exit(f"spectra at {times}, expected t = 0, 0.01, ..., 0.1 once each")
    print(f"restarted from {checkpoints[0]} after the end: {', '.join(indices)} as before, "
          f"each analysis time once", flush=True)


def main():
    sphles, scene, work = sys.argv[1:4]
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    env = dict(os.environ, OMP_NUM_THREADS="1")
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1):
        stop_by_signal([], sphles, scene, os.path.join(work, signum.name), signum, env)
    outputs_across_interrupt(sphles, os.path.join(work, "analysed"), env)
    outputs_after_a_crash(sphles, os.path.join(work, "crashed"), env)


if __name__ == "__main__":
    main()
