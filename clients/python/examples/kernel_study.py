#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""A kernel study through a sphles server: the 2D Taylor-Green vortex with each of three SPH
kernels (wendland_c4, wendland_c6, quintic_spline), queued on the server at once, and a table
of their errors against the references the service offers:

- the analytic decay e_v(t) = v0²/4 exp(-4νt) (GET /api/runs/{id}/reference): e_v at the end
  and the largest relative error over the run;
- the resolved energy against a spectral reference run of the same flow (GET
  /api/runs/{id}/resolved): its L2 misfit over time and its largest relative error. When the
  server has no reference of the flow, it computes one with --reference-points modes per side
  (0: skip these columns).

    python3 clients/python/examples/kernel_study.py [--url http://127.0.0.1:8080] [--token T]
        [--particles 32] [--end 1.0] [--reference-points 32]

The server runs --max-running runs at once (default 1) and queues the others; a full queue
(--max-queued) answers 429, and the study waits for a free place. Needs NumPy, not matplotlib.
"""

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np  # noqa: E402
from sphles_client import ApiError, Client  # noqa: E402

KERNELS = ["wendland_c4", "wendland_c6", "quintic_spline"]
COLUMNS = ["kernel", "steps", "wall_s", "e_v_end", "e_v_ref_end", "rel_err_end",
           "max_rel_err", "E_res_l2_misfit", "E_res_max_err"]


def create_queued(client, kernel, args, patience=600.0):
    """Creates and starts (or queues) the run of ``kernel``; waits while the queue is full."""
    patch = {"particles_per_side": args.particles, "kernel": {"type": kernel},
             "time": {"end": args.end},
             "analysis": {"every": args.end / 5, "products": ["energy", "spectrum"]}}
    deadline = time.monotonic() + patience
    while True:
        try:
            return client.create(preset="tgv2d", name=f"kernels-{kernel}", patch=patch)
        except ApiError as e:
            if e.status != 429 or time.monotonic() > deadline:
                raise
            time.sleep(1.0)


def resolved_scales(client, run_id, points):
    """The run's resolved-scale comparison; computes the flow's reference first if the server
    has none (one job serves every kernel: it is the same flow). None when ``points`` is 0."""
    if points == 0:
        return None
    try:
        return client.resolved(run_id)
    except ApiError as e:
        if e.status != 404:
            raise
    print(f"computing a {points}² spectral reference of the flow on the server")
    job = client.wait_reference(client.compute_reference(run_id, points_per_side=points)["id"])
    if job["state"] != "done":
        raise RuntimeError(f"reference job {job['id']} {job['state']}: {job['error']}")
    return client.resolved(run_id)


def row_of(client, kernel, summary, points):
    run_id = summary["id"]
    series = client.timeseries(run_id)
    reference = client.reference(run_id)
    analytic = np.interp(series["time"], reference["time"], reference["kinetic_energy"])
    relative = np.abs(series["kinetic_energy"] / analytic - 1)
    resolved = resolved_scales(client, run_id, points)
    misfit = resolved["resolved_energy_l2_misfit"] if resolved else np.nan
    worst = resolved["resolved_energy_max_relative_error"] if resolved else np.nan
    return [kernel, summary["step"], summary["wall_seconds"], series["kinetic_energy"][-1],
            analytic[-1], relative[-1], relative.max(), misfit, worst]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default=os.environ.get("SPHLES_URL", "http://127.0.0.1:8080"))
    parser.add_argument("--token", default=os.environ.get("SPHLES_TOKEN"))
    parser.add_argument("--particles", type=int, default=32, help="particles per side")
    parser.add_argument("--end", type=float, default=1.0, help="end time [s]")
    parser.add_argument("--reference-points", type=int, default=32,
                        help="modes per side of the spectral reference if the server has "
                             "none (even; 0: no resolved-scale columns)")
    args = parser.parse_args()

    client = Client(args.url, token=args.token)
    runs = {kernel: create_queued(client, kernel, args) for kernel in KERNELS}
    for kernel, run in runs.items():
        print(f"{run['id']}: {kernel}, {run['state']}")
    rows = []
    for kernel, run in runs.items():
        summary = client.wait(run["id"], timeout=3600)
        if summary["state"] != "finished":
            sys.exit(f"run {run['id']} ({kernel}) {summary['state']}: {summary['reason']}")
        rows.append(row_of(client, kernel, summary, args.reference_points))

    print(f"\n2D TGV, {args.particles}² particles, t = 0 to {args.end:g}; errors relative to "
          "the analytic e_v(t) and to the spectral reference's resolved energy")
    print(f"{COLUMNS[0]:<15}" + "".join(f"{name:>16}" for name in COLUMNS[1:]))
    print("-" * (15 + 16 * (len(COLUMNS) - 1)))
    for kernel, steps, *numbers in rows:
        print(f"{kernel:<15}{steps:>16d}" + "".join(f"{value:>16.6g}" for value in numbers))


if __name__ == "__main__":
    main()
