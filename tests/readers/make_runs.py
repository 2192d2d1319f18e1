#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Runs two small sphles scenes (3D and 2D Taylor-Green) that write every output kind a scene
can ask for: particle snapshots with fields, slices, gridded fields (3D), checkpoints. The reader tests
(check_h5py.py, check_paraview.py, the VTK tests) then open what they wrote.

usage: make_runs.py SPHLES_BINARY OUT_DIR
"""
import json
import pathlib
import shutil
import subprocess
import sys

def scene(name, case, per_side, analysis):
    return {
        "name": name,
        "case": case,
        "particles_per_side": per_side,
        "kernel": {"type": "wendland_c4", "diameter_over_spacing": 4},
        "packing": {"enabled": False},
        "time": {"end": 0.2},
        "checkpoint": {"every": 0.1, "keep": 3},
        "analysis": {"every": 0.1, **analysis},
    }


SCENES = {
    "3d": scene("readers-3d", "tgv3d", 12, {
        "products": ["energy", "vorticity", "slices", "particles", "fields"],
        "particle_fields": ["omega2", "tau_sfs"],
        "grid_fields": ["velocity", "omega2", "tau_sfs"],
        "slice": {"axis": "x", "position": 3.141592653589793, "fields": ["omega2", "tau_sfs"]},
    }),
    "2d": scene("readers-2d", "tgv2d", 16, {
        "products": ["energy", "vorticity", "slices", "particles"],
        "particle_fields": ["omega2"],
        "slice": {"fields": ["omega2"]},
    }),
}


def main():
    binary, out = sys.argv[1], pathlib.Path(sys.argv[2])
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    for key, scene in SCENES.items():
        scene_file = out / f"{key}.json"
        scene_file.write_text(json.dumps(scene, indent=2))
        result = subprocess.run(
            [binary, "run", str(scene_file), "--out", str(out / key), "--threads", "1"],
            capture_output=True, text=True, timeout=600)
        if result.returncode != 0:
            sys.exit(f"sphles run {key} failed ({result.returncode}):\n{result.stderr}")
        print(f"{key}: {result.stderr.strip().splitlines()[-1]}")


if __name__ == "__main__":
    main()
