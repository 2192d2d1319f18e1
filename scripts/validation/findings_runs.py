# SPDX-License-Identifier: GPL-3.0-or-later
"""The runs of the SPEC §7 findings campaign (run_findings.py) and how plot_findings.py reads them:
the run table, the run directories' files (timeseries, stats, spectra, slices), and the rows of
DOCS/validation_findings.csv as they are recorded."""

import csv
import json
import math
import os

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
REFERENCE = os.path.join(ROOT, "data", "reference", "tgv_re5000_incompact3d_1280_dairay2017.dat")
T_SPEC = 14.0  # time of spectra, slices and statistics; plot_findings.py --t-spectra sets it
NU = 1e-4

# name: (label, N per side, kernel, D_K/Δl, model note)
TGV_RUNS = {
    "case8_n24": ("WC4 8Δl 24³", 24, "WC4", 8),
    "case8_n32": ("WC4 8Δl 32³ (case 7/8)", 32, "WC4", 8),
    "case8_n48": ("WC4 8Δl 48³", 48, "WC4", 8),
    "case8_n48_t5": ("WC4 8Δl 48³ (to t = 5)", 48, "WC4", 8),
    "case1_n24": ("QS 6Δl 24³", 24, "QS", 6),
    "case1_n32": ("QS 6Δl 32³ (case 1)", 32, "QS", 6),
    "case5_n32": ("WC4 4Δl 32³ (case 5)", 32, "WC4", 4),
    "case6_n32": ("WC4 6Δl 32³ (case 6)", 32, "WC4", 6),
    "case12_n32": ("SMAG 0.15 (case 12)", 32, "WC4", 8),
    "case16_n32": ("SIGMA (case 16)", 32, "WC4", 8),
    "case17_n32": ("SMAG-MCG (case 17)", 32, "WC4", 8),
    "case18_n32": ("SMAG 0.075 (case 18)", 32, "WC4", 8),
    "case19_n32": ("SMAG 0.3 (case 19)", 32, "WC4", 8),
    "case20_n32": ("p_ref 68 (case 20)", 32, "WC4", 8),
    "case21_n32": ("p_ref 68, v_z+π, c_s 16.5 (case 21)", 32, "WC4", 8),
    # The transport-velocity scheme on the same cases (docs/validation.md): run_findings.py, TVF.
    "tvf_case8_n32": ("TVF: WC4 8Δl 32³ (case 8)", 32, "WC4", 8),
    "tvf_case1_n32": ("TVF: QS 6Δl 32³ (case 1)", 32, "QS", 6),
    "tvf_case5_n32": ("TVF: WC4 4Δl 32³ (case 5)", 32, "WC4", 4),
    "tvf_case12_n32": ("TVF: SMAG 0.15 (case 12)", 32, "WC4", 8),
    "tvf_case20_n32": ("TVF: p_b 68 (case 20)", 32, "WC4", 8),
    "tvf_case21_n32": ("TVF: p_b 68, v_z+π, c_s 16.5 (case 21)", 32, "WC4", 8),
}
# The TVF runs and their thesis-model counterparts (figure validation_tvf.png).
TVF_PAIRS = [("case8_n32", "tvf_case8_n32"), ("case1_n32", "tvf_case1_n32"),
             ("case5_n32", "tvf_case5_n32"), ("case12_n32", "tvf_case12_n32"),
             ("case20_n32", "tvf_case20_n32"), ("case21_n32", "tvf_case21_n32")]

rows = []  # (run, quantity, value, note)


def record(run, quantity, value, note=""):
    rows.append((run, quantity, value, note))
    return value


def read_csv(path):
    """Columns of a CSV with a header as a dict of numpy arrays (non-numeric columns as str)."""
    with open(path) as f:
        reader = csv.reader(f)
        header = next(reader)
        data = [r for r in reader if r]
    out = {}
    for i, h in enumerate(header):
        col = [r[i] if i < len(r) else "" for r in data]
        try:
            out[h] = np.array([float(x) if x not in ("", "nan") else np.nan for x in col])
        except ValueError:
            out[h] = np.array(col)
    return out


def tag(t):
    return f"{t:.4f}"


def load_reference():
    if not os.path.exists(REFERENCE):
        return None
    d = np.loadtxt(REFERENCE, comments="#")
    return {"t": d[:, 0], "e_v": d[:, 1], "eps": d[:, 2], "eps_nu": d[:, 3]}


def load_run(runs_dir, name):
    d = os.path.join(runs_dir, name)
    ts_file = os.path.join(d, "timeseries.csv")
    if not os.path.exists(ts_file):
        return None
    r = {"dir": d, "name": name, "ts": read_csv(ts_file)}
    # e_v (5.3) of a run with a uniform velocity U added (case 21) holds the mean-flow energy
    # ½|U|², constant because momentum is conserved to round-off (the TGV's own mean is zero by
    # symmetry); subtract it so that e_v is the energy of the flow relative to the mean, the
    # quantity that Galilean invariance says must match the run without U.
    scene_file = os.path.join(d, "scene.json")
    if os.path.exists(scene_file):
        u = json.load(open(scene_file)).get("flow", {}).get("uniform_velocity", [])
        mean_energy = 0.5 * sum(float(x) ** 2 for x in u)
        if mean_energy > 0.0:
            r["ts"]["e_v"] = r["ts"]["e_v"] - mean_energy
            r["mean_flow_energy"] = mean_energy
    wall = os.path.join(d, "wall.json")
    r["wall"] = json.load(open(wall)) if os.path.exists(wall) else None
    snap = os.path.join(d, "stats", "snapshots.csv")
    r["snap"] = read_csv(snap) if os.path.exists(snap) else None
    spec_index = os.path.join(d, "spectra", "index.csv")
    r["spec_index"] = read_csv(spec_index) if os.path.exists(spec_index) else None
    return r


def value_at(t, y, t0):
    """Linear interpolation of y at t0 (NaN outside the data)."""
    if len(t) == 0 or t0 < t[0] - 1e-9 or t0 > t[-1] + 1e-9:
        return math.nan
    return float(np.interp(t0, t, y))


def spectrum(run, t):
    f = os.path.join(run["dir"], "spectra", f"E_t{tag(t)}.csv")
    return read_csv(f) if os.path.exists(f) else None


def spectrum_row(run, t):
    si = run["spec_index"]
    if si is None:
        return None
    i = np.where(np.abs(si["t"] - t) < 1e-6)[0]
    return {k: si[k][i[0]] for k in si} if len(i) else None


def smooth_dissipation(t, ev, window=1.0, step=0.1):
    """-de_v/dt as the least-squares slope of e_v over a centred window (default 1.0), on a grid
    of spacing `step`. The run's own column uses a trailing 0.2 window, which keeps the acoustic
    oscillations of a coarse weakly compressible run; the wider window shows the trend."""
    grid = np.arange(t[0] + window / 2, t[-1] - window / 2 + 1e-9, step)
    out = np.full(len(grid), np.nan)
    for i, tc in enumerate(grid):
        m = np.abs(t - tc) <= window / 2
        if m.sum() >= 3:
            out[i] = -np.polyfit(t[m], ev[m], 1)[0]
    return grid, out


def local_maxima(t, y, lo, hi):
    m = (t >= lo) & (t <= hi)
    tt, yy = t[m], y[m]
    return [(tt[i], yy[i]) for i in range(1, len(tt) - 1)
            if yy[i] >= yy[i - 1] and yy[i] > yy[i + 1]]



def slice_pair(run, t):
    d = os.path.join(run["dir"], "slices")
    a, b = (os.path.join(d, f"{f}_t{tag(t)}.npy") for f in ("omega2", "tau_sfs"))
    if not (os.path.exists(a) and os.path.exists(b)):
        return None
    return np.load(a), np.load(b)


def joint(run, t):
    f = os.path.join(run["dir"], "stats", f"joint_tau_omega2_t{tag(t)}.csv")
    return read_csv(f) if os.path.exists(f) else None


def joint_correlation(j):
    x = 0.5 * (j["tau_lo"] + j["tau_hi"])
    y = 0.5 * (j["omega2_lo"] + j["omega2_hi"])
    w = j["count"]
    mx, my = np.average(x, weights=w), np.average(y, weights=w)
    cov = np.average((x - mx) * (y - my), weights=w)
    return float(cov / math.sqrt(np.average((x - mx) ** 2, weights=w) *
                                 np.average((y - my) ** 2, weights=w)))



def large_scale_energy(run):
    """Energy of the shells k <= 2 (the TGV's initial shell, |k| = √3, and larger scales) at every
    spectrum time: the same scales at every N."""
    si = run["spec_index"]
    if si is None:
        return None
    out = []
    for tq, kk in zip(si["t"], si["k_kernel"]):
        sp = spectrum(run, float(tq))
        if sp is not None:
            out.append((float(tq), float(np.sum(sp["E"][sp["k"] <= 2 + 1e-9]))))
    return np.array(out) if out else None


