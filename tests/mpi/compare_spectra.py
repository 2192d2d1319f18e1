# SPDX-License-Identifier: GPL-3.0-or-later
"""Spectra of two runs' spectra/ directories compared shell by shell (a distributed run's
spectra must equal one process's to 1e-12 relative). Shells below 1e-6 of a spectrum's largest
are compared against 1e-6 of it: the mean-removed k = 0 shell is round-off of both runs."""
import csv
import os

import numpy as np


def read_spectrum(path):
    """Columns of a spectra/ CSV file: numbers as arrays, the index's file names as a list."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return {name: [r[name] for r in rows] if name == "file"
            else np.array([float(r[name]) for r in rows]) for name in rows[0]}


def compare_spectra(one, two, label, rtol=1e-12):
    """Exits naming the file and column where the spectra (and their index.csv) of runs `one` and
    `two` differ by more than rtol; returns (spectra compared, largest relative difference)."""
    names = sorted(os.listdir(os.path.join(one, "spectra")))
    other = sorted(os.listdir(os.path.join(two, "spectra")))
    if "index.csv" not in names or len(names) < 2 or names != other:
        raise SystemExit(f"{label}: the runs wrote different spectra: {names} vs {other}")
    worst = 0.0
    for name in names:
        a = read_spectrum(os.path.join(one, "spectra", name))
        b = read_spectrum(os.path.join(two, "spectra", name))
        if sorted(a) != sorted(b):
            raise SystemExit(f"{label}: spectra/{name} has other columns: {sorted(a)} vs {sorted(b)}")
        for column in a:
            x, y = a[column], b[column]
            if isinstance(x, list):
                if x != y:
                    raise SystemExit(f"{label}: spectra/{name} {column}: {x} vs {y}")
                continue
            if x.shape != y.shape:
                raise SystemExit(f"{label}: spectra/{name} {column}: {x.shape} vs {y.shape} shells")
            scale = np.maximum(np.abs(x), 1e-6 * max(float(np.max(np.abs(x))), 1e-300))
            error = float(np.max(np.abs(x - y) / scale))
            if error > rtol:
                raise SystemExit(f"{label}: spectra/{name} {column} differs by {error:.3g} "
                                 f"relative (allowed {rtol:g})")
            worst = max(worst, error)
    return len(names) - 1, worst
