#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The Python client (clients/python/sphles_client.py) against a real `sphles serve`.

Usage: check_client.py SPHLES_BINARY WORK_DIR. Exits non-zero with the failed check."""

import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "clients", "python"))

import numpy as np  # noqa: E402
from service import start_server, stop_server  # noqa: E402
from sphles_client import ApiError, Client  # noqa: E402

TOKEN = "client-test-token"
SCENE = {"name": "client", "case": "tgv2d", "particles_per_side": 16,
         "packing": {"enabled": False}, "time": {"end": 0.3},
         "analysis": {"every": 0.1, "products": ["energy", "spectrum", "vorticity", "slices"],
                      "slice": {"fields": ["omega2"]}},
         "render": {"fields": ["omega2"], "combined": False, "width": 128, "height": 64},
         "checkpoint": {"every": 0.1}}


def check(condition, what):
    if not condition:
        sys.exit(f"check_client: FAILED: {what}")
    print(f"ok: {what}")


def main():
    binary, work = sys.argv[1], sys.argv[2]
    server, url, data = start_server(binary, work, token=TOKEN, name="check_client")
    try:
        anonymous = Client(url)
        client = Client(url, token=TOKEN)
        check(client.health()["status"] == "ok", "health")
        check(any(p["name"] == "tgv2d" for p in client.presets()), "presets list tgv2d")

        # Errors: the server's status, message and field.
        try:
            anonymous.create(scene=SCENE)
            check(False, "a mutating call without the token is refused")
        except ApiError as e:
            check(e.status == 401 and e.field == "Authorization", "401 without the token")
        try:
            client.create(scene=dict(SCENE, particles_per_side="many"))
            check(False, "a bad scene is refused")
        except ApiError as e:
            check(e.status == 400 and e.field == "particles_per_side",
                  f"400 naming the field: {e}")

        estimate = client.estimate(scene=SCENE)
        check(estimate["admitted"] and estimate["time"]["seconds_per_step"] > 0,
              "estimate with a measured time per step")

        run = client.create(scene=SCENE)
        run_id = run["id"]
        samples = list(client.stream_metrics(run_id, timeout=120))
        steps = [s["step"] for s in samples]
        check(len(samples) > 5 and steps == sorted(set(steps)) and steps[0] == 0,
              f"streamed {len(samples)} metrics samples in step order from step 0")
        summary = client.wait(run_id, timeout=120)
        check(summary["state"] == "finished", "the run finished")
        check(steps[-1] == summary["step"], "the stream's samples reach the last step")

        series = client.timeseries(run_id)
        check(np.array_equal(series["step"], np.arange(summary["step"] + 1)),
              "timeseries: every step as a NumPy array")
        check(abs(series["kinetic_energy"][0] - 0.25) < 0.01, "e_v(0) = v0²/4")
        check(np.allclose(series["kinetic_energy"][len(steps) - 1],
                          samples[-1]["kinetic_energy"], rtol=0, atol=0),
              "streamed and stored e_v agree bit for bit")
        decimated = client.timeseries(run_id, max_points=5)
        check(len(decimated["time"]) <= 5 and decimated["time"][-1] == series["time"][-1],
              "timeseries decimated by the server")

        k, energy = client.spectrum(run_id)
        check(k.shape == energy.shape and k.size > 3 and np.all(energy >= 0), "spectrum arrays")
        frames = client.analysis(run_id)
        check(np.allclose(frames["time"], [0.0, 0.1, 0.2, 0.3]), "analysis history of 4 frames")
        reference = client.reference(run_id)
        check(reference["label"] == "analytic decay" and reference["time"][-1] == 0.3,
              "reference curve")
        try:
            client.resolved(run_id)
            check(False, "resolved scales of a flow without a reference run")
        except ApiError as e:
            check(e.status == 404 and "sphles reference" in e.message,
                  f"no resolved scales without a reference run of the flow: {e.message}")
        estimate = client.estimate_reference(run_id, points_per_side=16)
        check(estimate["admitted"] and estimate["max_wavenumber"] == 5 and estimate["steps"] > 0
              and client.reference_jobs() == [],
              "the reference's estimate, nothing created")
        try:
            client.compute_reference(run_id, points_per_side=15)
            check(False, "an odd points_per_side is refused")
        except ApiError as e:
            check(e.status == 400 and e.field == "points_per_side", f"400 naming the field: {e}")
        job = client.compute_reference(run_id, points_per_side=16)
        job = client.wait_reference(job["id"], timeout=120)
        check(job["state"] == "done" and job["time"] == 0.3, f"reference job {job['id']} done")
        check(client.resolved(run_id)["reference"] == job["directory"],
              "resolved scales against the computed reference")
        plain, filtered = client.resolved(run_id), client.resolved(run_id, filter="kernel")
        check(filtered["filter"] == "kernel" and
              filtered["samples"][-1]["reference_resolved_energy"] <
              plain["samples"][-1]["reference_resolved_energy"],
              "against the kernel-filtered reference, less reference energy")
        try:
            client.resolved(run_id, filter="gaussian")
            check(False, "an unknown filter was accepted")
        except ApiError as e:
            check(e.status == 400 and e.field == "filter", f"400 naming the filter: {e}")

        omega2 = client.slice(run_id, "omega2")
        check(omega2.ndim == 2 and omega2.shape[0] > 8 and np.all(np.isfinite(omega2)),
              f"the latest ω² slice as a {omega2.shape} array")
        first = client.slice(run_id, "omega2", time=0.0)
        check(not np.array_equal(first, omega2), "the slice nearest t = 0 is another")

        try:
            client.movie(run_id, field="tau_sfs")
            check(False, "a movie of a series the run did not save")
        except ApiError as e:
            check(e.status == 404 and e.field == "field", f"404 naming the field: {e}")
        video = os.path.join(work, "omega2.webm")
        movie = client.movie(run_id, fps=5, destination=video)
        with open(video, "rb") as f:
            head = f.read(4)
        check(movie["path"] == "movies/omega2.webm" and movie["frames"] >= 2
              and head == b"\x1a\x45\xdf\xa3" and os.path.getsize(video) == movie["bytes"],
              f"a movie of the saved ω² frames ({movie['frames']} frames, WebM) downloaded")
        check(any(s["file"] == "tgv3d-accurate.json" for s in client.scenes()["scenes"]),
              "the server's scene files listed")

        files = {f["path"]: f for f in client.files(run_id)}
        checkpoint = max(p for p in files if p.startswith("checkpoints/") and p.endswith(".h5"))
        local = os.path.join(work, "ckpt.h5")
        content = client.download(run_id, checkpoint, local)
        with open(os.path.join(data, "runs", run_id, checkpoint), "rb") as f:
            check(content == f.read() and os.path.getsize(local) == files[checkpoint]["bytes"],
                  "a checkpoint downloaded byte for byte")
        check("state: running -> finished" in client.log(run_id), "run.log")

        client.change(run_id, {"time": {"end": 0.4}})
        client.start(run_id)
        check(client.wait(run_id, timeout=120)["time"] >= 0.4 - 1e-9,
              "a live change of time.end and a restart continue the run")
        client.delete(run_id)
        check(all(r["id"] != run_id for r in client.runs()), "deleted")
    finally:
        stop_server(server)
    print("check_client: all checks passed")


if __name__ == "__main__":
    main()
