#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Run control answers within a bound whatever a run's MPI job does (docs/api.md, "Stop").

Against a real `sphles serve --stop-grace 3` on a real port, with real ranks (mpiexec):
  1. a 2-rank run one of whose ranks is frozen (SIGSTOP, as a hung node): three concurrent stops
     all answer (one 200 once the job is given up, within the grace period and the job's end,
     the others 202 at once), while another run's pause and resume and the health check answer
     in under 2 s; the run is "stopped" at its last checkpoint, saying why, with no rank left;
     resumed, a new job continues from that checkpoint and stops normally;
  2. a launcher that never starts its job (a batch queue): a stop answers at once, the launcher
     is ended;
  3. SIGTERM ends a server with a frozen job within the grace period and the job's end.
Usage: check_service_mpi_faults.py SPHLES MPIEXEC WORKDIR
"""
import concurrent.futures
import os
import re
import shutil
import signal
import subprocess
import sys
import time

from check_service_mpi import command_lines, request, wait_for, wait_no_workers, worker_ranks

GRACE = 3.0
JOB_END = 15.0  # control::RunImpl::kJobEndSeconds
LONG = {"preset": "tgv2d", "patch": {"particles_per_side": 32, "time": {"end": 1e6},
                                     "checkpoint": {"every": 0.01, "keep": 3}}}


def start_server(sphles, work, name, launcher):
    env = dict(os.environ, OMP_NUM_THREADS="1", OMPI_ALLOW_RUN_AS_ROOT="1",
               OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMPI_MCA_mpi_yield_when_idle="1")
    server = subprocess.Popen(
        [sphles, "serve", "--port", "0", "--data", os.path.join(work, name), "--threads", "1",
         "--max-running", "3", "--launcher", launcher, "--stop-grace", str(GRACE)],
        env=env, stdout=subprocess.PIPE, stderr=open(os.path.join(work, name + ".log"), "w"),
        text=True)
    match = re.search(r"listening on (http://\S+?)/?$", server.stdout.readline().strip())
    if not match:
        server.kill()
        sys.exit(f"{name}: no 'listening on' line")
    return server, match.group(1)


def launchers(marker):
    """Process ids whose command line starts with `marker`."""
    return [pid for pid, argv in command_lines()
            if b" ".join(argv).decode(errors="replace").startswith(marker)]


def timed(call):
    start = time.time()
    result = call()
    return result, time.time() - start


def create(base, **fields):
    status, run = request(base, "POST", "/api/runs", dict(LONG, **fields))
    if status != 201:
        sys.exit(f"create {fields}: {status} {run}")
    return run["id"]


def frozen_job(base, sphles, data, name):
    """A 2-rank run stepping with checkpoints, one of whose ranks is then frozen."""
    run_id = create(base, name=name, ranks=2)
    wait_for(base, run_id, lambda r: r["state"] == "running" and r["step"] > 20, "stepping")
    checkpoints = os.path.join(data, "runs", run_id, "checkpoints")
    deadline = time.time() + 60
    while not any(f.endswith(".h5") for f in os.listdir(checkpoints)):
        if time.time() > deadline:
            sys.exit(f"{name}: no checkpoint written")
        time.sleep(0.1)
    ranks = worker_ranks(sphles)
    frozen = [pid for pid, rank in ranks.items() if rank == 1]
    if len(frozen) != 1:
        sys.exit(f"{name}: expected one rank 1 among {ranks}")
    os.kill(frozen[0], signal.SIGSTOP)
    time.sleep(1.0)
    return run_id, frozen[0]


def frozen_rank(sphles, base, data):
    run_id, _ = frozen_job(base, sphles, data, "frozen")
    local = create(base, name="local", ranks=1)
    wait_for(base, local, lambda r: r["state"] == "running", "running")
    with concurrent.futures.ThreadPoolExecutor(max_workers=6) as pool:
        stops = [pool.submit(timed, lambda: request(base, "POST", f"/api/runs/{run_id}/stop"))
                 for _ in range(3)]
        time.sleep(0.5)
        for path, method in ((f"/api/runs/{local}/pause", "POST"),
                             (f"/api/runs/{local}/resume", "POST"),
                             ("/api/health", "GET")):
            (status, body), seconds = timed(lambda: request(base, method, path))
            if status != 200 or seconds > 2.0:
                sys.exit(f"{method} {path} during the stops: {status} after {seconds:.1f} s: "
                         f"{body}")
        answers = [s.result() for s in stops]
    statuses = sorted(status for (status, _), _ in answers)
    slowest = max(seconds for _, seconds in answers)
    if statuses != [200, 202, 202] or slowest > GRACE + JOB_END:
        sys.exit(f"stops of a frozen job: statuses {statuses}, slowest {slowest:.1f} s")
    quick = [seconds for (status, _), seconds in answers if status == 202]
    if max(quick) > 2.0:
        sys.exit(f"a stop already under way answered after {max(quick):.1f} s")
    run = wait_for(base, run_id, lambda r: r["state"] != "running", "the end", timeout=30)
    reason = run["reason"]
    if run["state"] != "stopped" or f"within {GRACE:g} s of a stop" not in reason \
            or "last valid checkpoint" not in reason:
        sys.exit(f"the frozen run: {run['state']}: {reason}")
    wait_no_workers(sphles)
    stopped_at = run["time"]
    print(f"frozen rank: stops answered {statuses} in {slowest:.1f} s at most; "
          f"stopped at t = {stopped_at}: {reason[:120]}...")

    # Resumed: a new job continues from the last checkpoint, and stops normally.
    status, body = request(base, "POST", f"/api/runs/{run_id}/start")
    if status != 200:
        sys.exit(f"resume after the given-up job: {status} {body}")
    wait_for(base, run_id, lambda r: r["state"] == "running" and r["time"] > stopped_at + 0.02,
             "stepping again")
    (status, body), seconds = timed(lambda: request(base, "POST", f"/api/runs/{run_id}/stop"))
    if status != 200 or body["state"] != "stopped":
        sys.exit(f"a normal stop of the new job: {status} {body}")
    request(base, "POST", f"/api/runs/{local}/stop")
    wait_no_workers(sphles)
    print(f"resumed from the checkpoint, stopped normally in {seconds:.1f} s")


def never_connects(sphles, work):
    marker = "sleep 307"
    server, base = start_server(sphles, work, "queue", f"{marker}; true {{ranks}}")
    try:
        run_id = create(base, name="queued", ranks=2)
        wait_for(base, run_id, lambda r: r["state"] == "running", "running")
        time.sleep(1.0)
        if not launchers(marker):
            sys.exit("the launcher of the job that never connects is not running")
        (status, body), seconds = timed(lambda: request(base, "POST", f"/api/runs/{run_id}/stop"))
        if status != 200 or body["state"] != "stopped" or seconds > 10.0:
            sys.exit(f"stop of a job never started: {status} after {seconds:.1f} s: {body}")
        deadline = time.time() + 10
        while launchers(marker):
            if time.time() > deadline:
                sys.exit("the launcher of a job given up is still running")
            time.sleep(0.2)
        print(f"never-connecting job: stop answered in {seconds:.1f} s, launcher ended")
    finally:
        server.terminate()
        server.wait(timeout=60)


def terminate_with_frozen_job(sphles, base, data, server):
    frozen_job(base, sphles, data, "frozen-at-exit")
    start = time.time()
    server.terminate()
    try:
        server.wait(timeout=GRACE + JOB_END + 10)
    except subprocess.TimeoutExpired:
        server.kill()
        sys.exit("SIGTERM did not end a server with a frozen job")
    wait_no_workers(sphles)
    print(f"SIGTERM with a frozen job: the server ended in {time.time() - start:.1f} s")


def main():
    sphles, mpiexec, work = os.path.realpath(sys.argv[1]), sys.argv[2], sys.argv[3]
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    data = os.path.join(work, "mpi")
    server, base = start_server(sphles, work, "mpi",
                                f"{mpiexec} --oversubscribe --bind-to none -n {{ranks}}")
    try:
        frozen_rank(sphles, base, data)
        terminate_with_frozen_job(sphles, base, data, server)
    finally:
        if server.poll() is None:
            server.kill()
        for pid in worker_ranks(sphles):
            os.kill(pid, signal.SIGKILL)
    never_connects(sphles, work)
    print("ok")


if __name__ == "__main__":
    main()
