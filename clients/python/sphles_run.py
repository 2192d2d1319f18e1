# SPDX-License-Identifier: GPL-3.0-or-later
"""Reads a sphles run directory (docs/analysis.md, "Files in the run directory") as NumPy
arrays, without a server: the directory `sphles run --out DIR` writes, or a run of
`sphles serve` under DATA/runs/ID.

    from sphles_run import RunDirectory
    run = RunDirectory("runs/tgv2d")
    run.record["state"], run.scene["particles_per_side"]
    series = run.timeseries()             # {"t": array, "step": ..., "e_v": ..., ...}
    k, E = run.spectrum()                 # the latest spectrum; spectrum(t=1.0): the nearest
    omega2 = run.slice("omega2", t=1.0)   # a 2D array (height, width)
    particles = run.snapshot()            # {"position": (N, 3), "velocity": ..., ...}
    state = run.checkpoint()              # the newest checkpoint's particle arrays

Columns keep the names of the files (``t``, ``e_v``, ...), which the service's API renames
(``time``, ``kinetic_energy``). NumPy is needed; h5py (Debian's python3-h5py) only for
particle snapshots and checkpoints. A missing product or a time outside the written range
raises FileNotFoundError or ValueError naming the file and the reason.
"""

import csv
import json
import os
import re

import numpy as np

__all__ = ["RunDirectory", "Frame"]

# Which scene product writes each index file: a missing file is then explained by the scene.
_PRODUCT_OF = {
    "spectra/index.csv": "spectrum",
    "stats/snapshots.csv": "energy, spectrum, vorticity or sfs_stats",
    "slices/index.csv": "slices",
    "snapshots/index.csv": "particles",
}


class Frame(dict):
    """Arrays by name read from one HDF5 file, with the file's ``time``, ``step``, ``path`` and
    its other attributes in ``attrs`` (bytes decoded to str)."""

    def __init__(self, arrays, path, attrs):
        super().__init__(arrays)
        self.path = path
        self.attrs = attrs
        self.time = float(attrs.get("time", np.nan))
        self.step = int(attrs.get("step", -1))


def _decode(value):
    if isinstance(value, bytes):
        return value.decode(errors="replace")
    if isinstance(value, np.generic):
        return value.item()
    return value


def _column(values):
    """A CSV column as a float array when every cell is a number ("nan" included), as an
    array of strings otherwise (file names, units)."""
    try:
        return np.array([float(v) for v in values], dtype=float)
    except ValueError:
        return np.array(values, dtype=str)


class RunDirectory:
    """One run directory. Every call reads the files again, so a running run's directory shows
    what has been written so far."""

    def __init__(self, path):
        self.path = os.fspath(path)
        if not os.path.isdir(self.path):
            raise FileNotFoundError(f"{self.path}: no such run directory")
        if not os.path.isfile(os.path.join(self.path, "run.json")):
            raise FileNotFoundError(
                f"{os.path.join(self.path, 'run.json')}: missing, so {self.path} is not a run "
                "directory (sphles run --out DIR and sphles serve write run.json first)")

    def __repr__(self):
        return f"RunDirectory({self.path!r})"

    # -- plumbing -------------------------------------------------------------------------------

    def _file(self, relative, product=None):
        """The full path of ``relative``; FileNotFoundError saying which product writes it."""
        full = os.path.join(self.path, relative)
        if os.path.isfile(full):
            return full
        product = product or _PRODUCT_OF.get(relative)
        reason = "not written"
        if product:
            asked = self.scene.get("analysis", {}).get("products", [])
            if any(name.strip() in asked for name in product.replace(" or ", ",").split(",")):
                reason = (f"missing, although the scene asks for analysis product {product} "
                          "(not written yet, or removed)")
            else:
                reason = (f"not written: it needs analysis product {product}, and the scene's "
                          f"analysis.products are [{', '.join(asked)}]")
        raise FileNotFoundError(f"{full}: {reason}")

    def _json(self, relative):
        with open(self._file(relative), encoding="utf-8") as f:
            return json.load(f)

    def _csv(self, relative, product=None):
        """A CSV file as {column: array}; an empty file (header only) gives empty arrays."""
        full = self._file(relative, product)
        with open(full, newline="", encoding="utf-8") as f:
            reader = csv.reader(f)
            try:
                header = next(reader)
            except StopIteration:
                raise ValueError(f"{full}: empty file, no header") from None
            rows = [row for row in reader if row]
        for number, row in enumerate(rows, start=2):
            if len(row) != len(header):
                raise ValueError(f"{full}: line {number} has {len(row)} cells, the header "
                                 f"{len(header)}")
        columns = {}
        for i, name in enumerate(header):
            columns[name] = _column([row[i] for row in rows])
        if "step" in columns and columns["step"].dtype.kind == "f":
            columns["step"] = columns["step"].astype(np.int64)
        return columns

    def _pick(self, index, relative, t):
        """The row number of ``index`` (a CSV as columns) nearest to ``t``, or the last row for
        None. Among equal times the later row wins: a restarted run appends the newer one."""
        full = os.path.join(self.path, relative)
        times = index["t"]
        if times.size == 0:
            raise ValueError(f"{full}: no rows written yet")
        if t is None:
            return times.size - 1
        t = float(t)
        slack = 1e-9 * max(1.0, abs(times.max()))
        if not np.isfinite(t) or t < times.min() - slack or t > times.max() + slack:
            raise ValueError(f"{full}: t = {t:g} is outside the written range "
                             f"[{times.min():g}, {times.max():g}]")
        distance = np.abs(times - t)
        return int(np.flatnonzero(distance == distance.min())[-1])

    def _h5(self, full, group=None):
        try:
            import h5py  # Debian python3-h5py
        except ImportError:
            raise ImportError(f"reading {full} needs h5py: install python3-h5py") from None
        arrays = {}
        with h5py.File(full, "r") as f:
            root = f[group] if group and group in f else f

            def visit(name, item):
                if isinstance(item, h5py.Dataset):
                    arrays[name] = item[()]
            root.visititems(visit)
            attrs = {key: _decode(value) for key, value in f.attrs.items()}
        return Frame(arrays, full, attrs)

    # -- records --------------------------------------------------------------------------------

    @property
    def record(self):
        """run.json as a dict: state, step, time, and once the run ended the ``outputs``."""
        return self._json("run.json")

    @property
    def scene(self):
        """scene.json (the full scene with its defaults) as a dict."""
        return self._json("scene.json")

    def timeseries(self):
        """timeseries.csv as arrays by column: t, step, dt, e_v, dissipation,
        max_density_deviation, max_speed."""
        return self._csv("timeseries.csv")

    def units(self, relative="timeseries.csv"):
        """{column: unit} of a CSV file of the run (its path in the run directory, e.g.
        "spectra/E_t0.5000.csv"), from the run's units.csv: SI in ASCII ("m^2/s^3"), "1" for a
        pure number, "-" for text."""
        table = self._csv("units.csv")
        out = {}
        for pattern, column, unit in zip(table["file"], table["column"], table["unit"]):
            head, star, tail = pattern.partition("*")
            if (relative == pattern or (star and relative.startswith(head)
                                        and relative.endswith(tail))):
                out[column] = unit
        if not out:
            raise ValueError(f"{os.path.join(self.path, 'units.csv')}: no columns of {relative}")
        return out

    def analysis(self):
        """stats/snapshots.csv, every analysis frame's scalars, as arrays by column: t, step,
        e_v, e_v_grid, mean_omega2, the dissipation three ways, tau_sfs_max, ..."""
        return self._csv("stats/snapshots.csv")

    # -- spectra --------------------------------------------------------------------------------

    def spectra_index(self):
        """spectra/index.csv as arrays by column (t, step, file, e_v_grid, delta_k, ...)."""
        return self._csv("spectra/index.csv")

    def spectrum_times(self):
        """The times of the written spectra."""
        return self.spectra_index()["t"]

    def spectrum(self, t=None, columns=False):
        """The energy spectrum nearest to ``t`` (the latest for None) as (k, E) arrays, k in
        1/m and E in m³/s², with Σ E Δk = ½⟨|u'|²⟩ of the grid (``e_v_grid``). With
        ``columns`` the whole file as a dict (k, E, k_Lc, E_over_ev_Lc) plus ``t`` and
        ``delta_k``."""
        index = self.spectra_index()
        row = self._pick(index, "spectra/index.csv", t)
        data = self._csv(os.path.join("spectra", str(index["file"][row])), "spectrum")
        if columns:
            return dict(data, t=float(index["t"][row]), delta_k=float(index["delta_k"][row]))
        return data["k"], data["E"]

    # -- slices ---------------------------------------------------------------------------------

    def slices_index(self):
        """slices/index.csv as arrays by column (t, step, field, width, height, spacing, ...)."""
        return self._csv("slices/index.csv")

    def slice_fields(self):
        """The fields with saved slices (omega2, tau_sfs, nu_t), in the order first written."""
        return list(dict.fromkeys(self.slices_index()["field"].tolist()))

    def _slice_rows(self, field):
        index = self.slices_index()
        chosen = index["field"] == field
        if not chosen.any():
            raise FileNotFoundError(
                f"{os.path.join(self.path, 'slices/index.csv')}: no slice of {field!r} written "
                f"(fields: {', '.join(self.slice_fields()) or 'none'}; analysis.slice.fields "
                "chooses them)")
        return {name: values[chosen] for name, values in index.items()}

    def slice_times(self, field):
        """The times of the saved slices of ``field``."""
        return self._slice_rows(field)["t"]

    def slice(self, field, t=None):
        """The slice of ``field`` nearest to ``t`` (the latest for None) as a 2D float64 array
        of shape (height, width), rows along the plane's axis_v, columns along axis_u (both
        in slices/index.csv)."""
        rows = self._slice_rows(field)
        row = self._pick(rows, "slices/index.csv", t)
        full = self._file(os.path.join("slices", str(rows["file"][row])), "slices")
        array = np.load(full, allow_pickle=False)
        expected = (int(rows["height"][row]), int(rows["width"][row]))
        if array.shape != expected:
            raise ValueError(f"{full}: shape {array.shape}, slices/index.csv says {expected}")
        return array

    # -- particle snapshots and checkpoints -----------------------------------------------------

    def snapshot_times(self):
        """The times of the particle snapshots (product ``particles``)."""
        return self._csv("snapshots/index.csv")["t"]

    def snapshot(self, t=None):
        """The particle snapshot nearest to ``t`` (the latest for None) as a Frame: position
        and velocity (N, 3) (z = 0 in 2D), density, pressure, mass, id and the
        ``particle_fields`` (omega2, tau_sfs, nu_t); row k is particle id k."""
        index = self._csv("snapshots/index.csv")
        row = self._pick(index, "snapshots/index.csv", t)
        return self._h5(self._file(os.path.join("snapshots", str(index["file"][row])),
                                   "particles"))

    def checkpoints(self):
        """The checkpoint files (checkpoints/*_STEP.h5), oldest first."""
        folder = os.path.join(self.path, "checkpoints")
        names = os.listdir(folder) if os.path.isdir(folder) else []
        steps = {}
        for name in names:
            # Files being written are NAME.tmp.PID, so the pattern leaves them out.
            match = re.fullmatch(r"[A-Za-z]+_(\d+)\.h5", name)
            if match:
                steps[name] = int(match.group(1))
        return sorted(steps, key=steps.get)

    def checkpoint(self, name=None):
        """A checkpoint's particle arrays (the newest, or the file ``name`` of
        ``checkpoints()``) as a Frame: position_x, velocity_x, ..., density, pressure, mass,
        volume, id, in cell order (``id`` gives each row's particle)."""
        names = self.checkpoints()
        folder = os.path.join(self.path, "checkpoints")
        if not names:
            raise FileNotFoundError(f"{folder}: no checkpoint written (checkpoint.every, "
                                    "and every run's end, write them)")
        if name is None:
            name = names[-1]
        elif os.path.basename(name) not in names:
            raise FileNotFoundError(f"{os.path.join(folder, os.path.basename(name))}: no such "
                                    f"checkpoint (written: {', '.join(names)})")
        return self._h5(os.path.join(folder, os.path.basename(name)), "particles")
