#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Runs a small 2D Taylor-Green vortex on a sphles server and plots it against its reference:
e_v(t) with the analytic decay, the energy spectrum E(k) with a k^(-5/3) guide, and the last
ω² slice. Writes the figure to OUT (default tgv2d.png).

    python3 clients/python/examples/plot_run.py [--url http://127.0.0.1:8080] [--token T]
        [--particles 48] [--end 2.0] [--out tgv2d.png]
"""

import argparse
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from sphles_client import Client  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default=os.environ.get("SPHLES_URL", "http://127.0.0.1:8080"))
    parser.add_argument("--token", default=os.environ.get("SPHLES_TOKEN"))
    parser.add_argument("--particles", type=int, default=48)
    parser.add_argument("--end", type=float, default=2.0)
    parser.add_argument("--out", default="tgv2d.png")
    args = parser.parse_args()

    client = Client(args.url, token=args.token)
    scene = {"name": "tgv2d-example", "case": "tgv2d", "particles_per_side": args.particles,
             "time": {"end": args.end},
             "analysis": {"every": args.end / 10,
                          "products": ["energy", "spectrum", "vorticity", "slices"],
                          "slice": {"fields": ["omega2"]}}}
    run = client.create(scene=scene)
    print(f"run {run['id']}: streaming until it finishes")
    for sample in client.stream_metrics(run["id"], timeout=600):
        if sample["step"] % 50 == 0:
            print(f"  t = {sample['time']:.3f}  e_v = {sample['kinetic_energy']:.6f}")
    client.wait(run["id"])

    series = client.timeseries(run["id"])
    reference = client.reference(run["id"])
    k, energy = client.spectrum(run["id"])
    omega2 = client.slice(run["id"], "omega2")

    fig, (a, b, c) = plt.subplots(1, 3, figsize=(14, 4.2))
    a.plot(series["time"], series["kinetic_energy"], label="sphles")
    a.plot(reference["time"], reference["kinetic_energy"], "k--", label=reference["label"])
    a.set(xlabel="t [s]", ylabel="e_v [m²/s²]", title="kinetic energy")
    a.legend()
    positive = energy > 0
    b.loglog(k[positive], energy[positive], "o-", ms=3, label="E(k)")
    peak = np.argmax(energy)
    b.loglog(k[peak:], energy[peak] * (k[peak:] / k[peak]) ** (-5 / 3), "k:", label="k^(-5/3)")
    b.set(xlabel="k [1/m]", ylabel="E(k) [m³/s²]", title=f"spectrum at t = {args.end:g} s",
          ylim=(energy.max() * 1e-8, energy.max() * 3))
    b.legend()
    image = c.imshow(omega2.T, origin="lower", cmap="viridis",
                     norm=matplotlib.colors.LogNorm(vmin=max(omega2.min(), 1e-6 * omega2.max()),
                                                    vmax=omega2.max()))
    fig.colorbar(image, ax=c, label="ω² [1/s²]")
    c.set(title="ω² slice", xticks=[], yticks=[])
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
