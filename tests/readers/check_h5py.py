#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Reads every HDF5 output of the runs made by make_runs.py back with h5py (a real reader) and
checks it against the XDMF files that describe it and against each other.

- every dataset of every snapshot and checkpoint has a "units" attribute; every file has the
  schema, schema_version and code_version attributes and a scene that is JSON;
- every DataItem of particles.xdmf and of each checkpoint's .xdmf2 side file names an existing
  dataset with the declared shape and number type (Function items: their arguments);
- a snapshot's rows are in id order (row k holds id k), and agree exactly with the checkpoint
  written at the same step once that is put in id order;
- the index files list exactly the requested times.

usage: check_h5py.py RUNS_DIR
"""
import json
import math
import pathlib
import sys
import xml.etree.ElementTree as ET

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from common import check, failures, finish, index_rows  # noqa: E402

import h5py
import numpy as np

def text(value):
    return value.decode() if isinstance(value, bytes) else str(value)


def check_file_attributes(f, path, schema):
    for name in ("schema", "schema_version", "code_version", "scene", "time", "step", "dimension"):
        check(name in f.attrs, f"{path}: root attribute '{name}' missing")
    check(text(f.attrs.get("schema", b"")) == schema, f"{path}: schema is not {schema}")
    check(text(f.attrs.get("code_version", b"")) not in ("", "unknown"),
          f"{path}: code_version is empty")
    try:
        check(isinstance(json.loads(text(f.attrs["scene"])), dict), f"{path}: scene is no object")
    except (KeyError, ValueError) as e:
        failures.append(f"{path}: scene attribute is not JSON ({e})")

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset):
            check("units" in obj.attrs and text(obj.attrs["units"]) != "",
                  f"{path}: dataset '{name}' has no units attribute")
    f.visititems(visit)


NUMBER_TYPES = {("Float", "8"): np.float64, ("UInt", "8"): np.uint64}


def check_data_item(item, base, path, expected_rows):
    if item.get("ItemType") == "Function":
        args = item.findall("DataItem")
        check(len(args) >= 2, f"{path}: function item with {len(args)} arguments")
        for a in args:
            check_data_item(a, base, path, expected_rows)
        return
    check(item.get("Format") == "HDF", f"{path}: DataItem format {item.get('Format')}")
    file_name, dataset = item.text.strip().split(":", 1)
    h5 = base / file_name
    check(h5.exists(), f"{path}: refers to missing file {file_name}")
    if not h5.exists():
        return
    with h5py.File(h5, "r") as f:
        check(dataset in f, f"{path}: {file_name} has no dataset {dataset}")
        if dataset not in f:
            return
        d = f[dataset]
        dims = tuple(int(x) for x in item.get("Dimensions").split())
        check(d.shape == dims, f"{path}: {dataset} has shape {d.shape}, the XDMF says {dims}")
        check(d.shape[0] == expected_rows, f"{path}: {dataset} has {d.shape[0]} rows")
        kind = NUMBER_TYPES.get((item.get("NumberType"), item.get("Precision")))
        check(kind is not None and d.dtype == kind,
              f"{path}: {dataset} is {d.dtype}, the XDMF says {item.get('NumberType')}")
        d[...]  # every byte reads


def check_xdmf(path, rows_of):
    root = ET.parse(path).getroot()
    grids = [g for g in root.iter("Grid") if g.get("GridType") == "Uniform"]
    check(len(grids) > 0, f"{path}: no grid")
    for g in grids:
        topology = g.find("Topology")
        check(topology.get("TopologyType") == "Polyvertex", f"{path}: topology is not Polyvertex")
        check(topology.find("DataItem") is not None, f"{path}: topology without connectivity")
        items = g.findall("Topology/DataItem") + g.findall("Geometry/DataItem") + \
            g.findall("Attribute/DataItem")
        first = items[0]
        file_name = (first.findall("DataItem")[0] if first.get("ItemType") == "Function"
                     else first).text.split(":")[0]
        rows = rows_of(file_name)
        check(int(topology.get("NumberOfElements")) == rows, f"{path}: NumberOfElements")
        for item in items:
            check_data_item(item, path.parent, path, rows)
        names = [a.get("Name") for a in g.findall("Attribute")]
        for name in ("id", "velocity", "mass", "density", "pressure"):
            check(name in names, f"{path}: attribute {name} missing")
    return grids


def check_run(run, dimension, requested):
    snapshots = run / "snapshots"
    rows = index_rows(snapshots / "index.csv")
    times = [float(r["t"]) for r in rows]
    check(len(times) == len(requested) and
          all(math.isclose(a, b, abs_tol=1e-9) for a, b in zip(times, requested)),
          f"{run}: snapshot times {times}, requested {requested}")
    slice_times = sorted({float(r["t"]) for r in index_rows(run / "slices" / "index.csv")})
    check(len(slice_times) == len(requested), f"{run}: slice times {slice_times}")

    counts = {}
    for r in rows:
        h5 = snapshots / r["file"]
        with h5py.File(h5, "r") as f:
            check_file_attributes(f, h5, "sphles-particles")
            check(int(f.attrs["schema_version"]) == 2, f"{h5}: schema_version")
            check(int(f.attrs["dimension"]) == dimension, f"{h5}: dimension")
            n = int(f.attrs["num_particles"])
            counts[r["file"]] = n
            check(np.array_equal(f["id"][...], np.arange(n, dtype=np.uint64)),
                  f"{h5}: rows are not in id order")
            check(f["position"].shape == (n, 3) and f["velocity"].shape == (n, 3),
                  f"{h5}: position/velocity shape")
            if dimension == 2:
                check(np.all(f["position"][:, 2] == 0.0), f"{h5}: 2D z is not 0")
            for field in r["fields"].split(";"):
                if field:
                    check(field in f and f[field].shape == (n,), f"{h5}: field {field}")
    check_xdmf(snapshots / "particles.xdmf", lambda name: counts[name])

    checkpoints = sorted((run / "checkpoints").glob("ckpt_*.h5"))
    check(len(checkpoints) >= 2, f"{run}: {len(checkpoints)} checkpoints")
    for c in checkpoints:
        side = c.with_suffix(".xdmf2")
        check(side.exists(), f"{c}: no XDMF side file")
        with h5py.File(c, "r") as f:
            check_file_attributes(f, c, "sphles-checkpoint")
            n = int(f.attrs["num_particles"])
        if side.exists():
            check_xdmf(side, lambda name: n)
    # The same state twice: the snapshot at the time of a checkpoint is that checkpoint in id
    # order, bit for bit.
    matched = 0
    for c in checkpoints:
        with h5py.File(c, "r") as ck:
            t = float(ck.attrs["time"])
            row = next((r for r in rows if math.isclose(float(r["t"]), t, abs_tol=1e-12)), None)
            if row is None:
                continue
            order = np.argsort(ck["particles/id"][...])
            with h5py.File(snapshots / row["file"], "r") as s:
                for d, axis in enumerate("xyz"[:dimension]):
                    for q in ("position", "velocity"):
                        check(np.array_equal(ck[f"particles/{q}_{axis}"][...][order], s[q][:, d]),
                              f"{c}: {q}_{axis} differs from the snapshot at t = {t}")
                for q in ("mass", "density", "pressure"):
                    check(np.array_equal(ck[f"particles/{q}"][...][order], s[q][...]),
                          f"{c}: {q} differs from the snapshot at t = {t}")
            matched += 1
    check(matched >= 1, f"{run}: no checkpoint at a snapshot time")


def main():
    runs = pathlib.Path(sys.argv[1])
    check_run(runs / "3d", 3, [0.0, 0.1, 0.2])
    check_run(runs / "2d", 2, [0.0, 0.1, 0.2])
    finish()


if __name__ == "__main__":
    main()
