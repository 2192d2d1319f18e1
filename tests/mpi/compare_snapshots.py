# SPDX-License-Identifier: GPL-3.0-or-later
"""Particle snapshots and grid fields of two runs compared: the files a distributed run's ranks
write, each its block of the particles, and the grid fields they compute must equal one process's
bit for bit."""
import os
import sys

import h5py
import numpy as np


def same_particle_snapshots(reference, other, label, count, fields, unlike=()):
    """Every particle snapshot (written by the ranks, each its block, into one file) holds the
    one-process file's attributes (but those named in `unlike`, e.g. the scene of a run with
    another name) and datasets bit for bit; index.csv and the XDMF series are the same bytes."""
    directory = os.path.join(reference, "snapshots")
    names = sorted(n for n in os.listdir(directory) if n.endswith(".h5"))
    if len(names) != count or names != sorted(
            n for n in os.listdir(os.path.join(other, "snapshots")) if n.endswith(".h5")):
        sys.exit(f"{label}: expected the same {count} particle snapshots, found {names}")
    for name in names:
        with h5py.File(os.path.join(directory, name), "r") as a, \
                h5py.File(os.path.join(other, "snapshots", name), "r") as b:
            attributes = [{k: v for k, v in f.attrs.items() if k not in unlike} for f in (a, b)]
            if attributes[0] != attributes[1] or sorted(a) != sorted(b):
                sys.exit(f"{label}: {name}: attributes or datasets differ from one process")
            if sorted(a) != sorted(["id", "position", "velocity", "mass", "density", "pressure",
                                    *fields]):
                sys.exit(f"{label}: {name}: unexpected datasets {sorted(a)}")
            for key in a:
                if a[key].attrs["units"] != b[key].attrs["units"] or \
                        not np.array_equal(a[key][()], b[key][()]):
                    sys.exit(f"{label}: {name}: dataset {key} differs from one process")
    same_bytes(reference, other, "snapshots", ("index.csv", "particles.xdmf"), label)
    print(f"{label}: {len(names)} particle snapshots written by the ranks equal one process's "
          "bit for bit")


def same_grid_fields(reference, other, label, count):
    """Every file of fields/ (the VTK image data of the whole analysis grid, its index and the
    ParaView series) is the same bytes in both runs."""
    names = sorted(os.listdir(os.path.join(reference, "fields")))
    if len([n for n in names if n.endswith(".vti")]) != count or \
            names != sorted(os.listdir(os.path.join(other, "fields"))):
        sys.exit(f"{label}: expected the same {count} grid field files, found {names}")
    same_bytes(reference, other, "fields", names, label)
    print(f"{label}: {count} grid fields computed on the ranks equal one process's byte for byte")


def same_bytes(reference, other, directory, names, label):
    """Exits naming the first of `names` in `directory` whose bytes differ between the runs."""
    for name in names:
        with open(os.path.join(reference, directory, name), "rb") as x, \
                open(os.path.join(other, directory, name), "rb") as y:
            if x.read() != y.read():
                sys.exit(f"{label}: {directory}/{name} differs from one process")
