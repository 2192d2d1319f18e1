#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Figures and numbers of the SPEC §7 findings from the runs of run_findings.py.

    /usr/bin/python3 scripts/validation/plot_findings.py [--runs runs/validation] [--docs docs]

Reads RUNS/NAME/{timeseries.csv, stats/, spectra/, slices/, wall.json} for every run that
exists (missing runs are left out of the figures and listed), writes
DOCS/figures/validation_*.png and DOCS/validation_findings.csv (columns run, quantity, value,
note): every number docs/validation.md quotes. Needs python3, numpy and matplotlib only.
"""

import argparse
import csv
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
REFERENCE = os.path.join(ROOT, "data", "reference", "tgv_re5000_incompact3d_1280_dairay2017.dat")
T_SPEC = 14.0
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
GROUPS = [
    ("kernel, D_K/Δl and N", ["case8_n24", "case8_n32", "case8_n48", "case8_n48_t5", "case1_n24", "case1_n32",
                              "case5_n32", "case6_n32"]),
    ("sub-filter models (32³, WC4 8Δl)", ["case8_n32", "case12_n32", "case16_n32", "case17_n32",
                                          "case18_n32", "case19_n32"]),
    ("background pressure (32³, WC4 8Δl)", ["case8_n32", "case20_n32", "case21_n32"]),
]
STYLE = {
    "case8_n24": dict(color="tab:blue", ls=":"), "case8_n32": dict(color="tab:blue", ls="-"),
    "case8_n48": dict(color="tab:blue", ls="--", lw=2),
    "case8_n48_t5": dict(color="navy", ls="--", lw=2),
    "case1_n24": dict(color="tab:orange", ls=":"), "case1_n32": dict(color="tab:orange", ls="-"),
    "case5_n32": dict(color="tab:red", ls="-"), "case6_n32": dict(color="tab:purple", ls="-"),
    "case12_n32": dict(color="tab:green", ls="-"), "case16_n32": dict(color="tab:olive", ls="-"),
    "case17_n32": dict(color="tab:cyan", ls="-"), "case18_n32": dict(color="tab:green", ls=":"),
    "case19_n32": dict(color="tab:green", ls="--"),
    "case20_n32": dict(color="tab:brown", ls="-"), "case21_n32": dict(color="tab:pink", ls="--"),
    "tvf_case8_n32": dict(color="tab:blue", ls="-"), "tvf_case1_n32": dict(color="tab:orange", ls="-"),
    "tvf_case5_n32": dict(color="tab:red", ls="-"), "tvf_case12_n32": dict(color="tab:green", ls="-"),
    "tvf_case20_n32": dict(color="tab:brown", ls="-"),
    "tvf_case21_n32": dict(color="tab:pink", ls="--"),
}

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


def tgv_numbers(run, ref):
    name = run["name"]
    ts = run["ts"]
    t, ev, eps = ts["t"], ts["e_v"], ts["dissipation"]
    t_end = float(t[-1])
    if run["wall"]:
        record(name, "wall_seconds", round(run["wall"]["wall_seconds"], 1),
               f"sphles run, --threads {run['wall']['threads']}")
        record(name, "exit_code", run["wall"]["exit_code"])
    record(name, "t_end", round(t_end, 4))
    record(name, "steps", int(ts["step"][-1]))
    ev0 = float(ev[0])
    record(name, "e_v(0)", ev0)
    for tq in (5.0, 9.0, 14.0):
        record(name, f"e_v({tq:g})", value_at(t, ev, tq))
    record(name, "e_v(5)/e_v(0)", value_at(t, ev, 5.0) / ev0,
           "laminar-phase energy kept")
    record(name, "max_density_deviation_max", float(np.nanmax(ts["max_density_deviation"])))
    record(name, "max_density_deviation(t=5)",
           value_at(t, ts["max_density_deviation"], 5.0))
    if t_end >= 3.0:
        g, eg = smooth_dissipation(t, ev)
        run["eps_smooth"] = (g, eg)
        m = (g >= 3.0) & np.isfinite(eg)
        if m.any():
            i = np.argmax(np.where(m, eg, -np.inf))
            record(name, "eps_peak", float(eg[i]), "max of -de_v/dt (1.0 centred window), t >= 3")
            record(name, "t_eps_peak", float(g[i]))
            late = local_maxima(g, eg, float(g[i]) + 1.0, 14.0)
            if late:
                tp, ep = max(late, key=lambda p: p[1])
                record(name, "t_eps_second_peak", float(tp), "largest local max after t_peak + 1")
                record(name, "eps_second_peak", float(ep))
        record(name, "eps_smooth(14)", value_at(g[np.isfinite(eg)], eg[np.isfinite(eg)], T_SPEC),
               "-de_v/dt, 1.0 centred window")
        i0 = (g <= 3.0)
        if i0.any():
            record(name, "eps_early_max", float(np.nanmax(eg[i0])), "max of smoothed -de_v/dt, t <= 3")
            record(name, "t_eps_early_max", float(g[i0][np.nanargmax(eg[i0])]))
    # Decay law e_v ~ t^-a over [10, 15] (the thesis: a = 1.2 after the peak at t ≈ 9).
    m = (t >= 10.0) & (t <= 15.0) & (ev > 0)
    if m.sum() > 10 and t_end >= 14.9:
        a = -np.polyfit(np.log(t[m]), np.log(ev[m]), 1)[0]
        record(name, "decay_exponent", float(a), "fit e_v ~ t^-a over [10, 15]")
    snap = run["snap"]
    if snap is not None:
        j = np.where(np.abs(snap["t"] - T_SPEC) < 1e-6)[0]
        if len(j):
            j = j[0]
            record(name, "eps_vorticity(14)", float(snap["dissipation_vorticity"][j]),
                   "nu <omega^2> on the grid")
            record(name, "eps_spectral(14)", float(snap["dissipation_spectral"][j]),
                   "2 nu sum k^2 E dk, all shells")
            record(name, "eps_history(14)", value_at(t, eps, T_SPEC), "-de_v/dt")
            record(name, "tau_sfs_mean(14)", float(snap["tau_sfs_mean"][j]))
            record(name, "tau_sfs_max(14)", float(snap["tau_sfs_max"][j]))
            record(name, "tau_sfs_mean/e_v(14)",
                   float(snap["tau_sfs_mean"][j]) / value_at(t, ev, T_SPEC))
        asec = snap["analysis_seconds"]
        record(name, "analysis_seconds_total", round(float(np.nansum(asec)), 1))
    sr0 = spectrum_row(run, 0.0)
    if sr0 is not None:
        kk, kr = float(sr0["k_kernel"]), float(sr0["k_resolution"])
        record(name, "k_kernel", kk, "2π/D_K")
        record(name, "k_resolution", kr, "π/Δl")
        ls = large_scale_energy(run)
        for tq in (0.0, 5.0, 9.0, T_SPEC):
            i = np.where(np.abs(ls[:, 0] - tq) < 1e-6)[0] if ls is not None else []
            if len(i):
                record(name, f"energy_k<=2({tq:g})", float(ls[i[0], 1]),
                       "energy of the TGV shell |k| = √3 and larger scales")
        for tq in (0.0, 2.0, 5.0, 9.0, T_SPEC):
            sq = spectrum(run, tq)
            if sq is not None:
                record(name, f"energy_fraction_k>k_kern({tq:g})",
                       float(np.sum(sq["E"][sq["k"] > kk])) / float(np.sum(sq["E"])),
                       "share of the gridded e_v below the kernel scale (noise)")
                # k_SPH: where the kernel-scale noise overtakes the resolved signal, i.e. the
                # minimum of E(k) between the large-scale peak (k <= max(k_kern/2, 2)) and k_res.
                if tq >= 5.0:
                    k, e = sq["k"], sq["E"]
                    lo = (k > 0) & (k <= max(kk / 2, 2.0))
                    kpeak = float(k[lo][np.argmax(e[lo])])
                    m = (k >= kpeak) & (k <= kr)
                    kmin = float(k[m][np.argmin(e[m])])
                    record(name, f"k_SPH({tq:g})", kmin,
                           "minimum of E(k) between the large-scale peak and k_res")
                    record(name, f"k_SPH/k_kernel({tq:g})", kmin / kk)
    sr = spectrum_row(run, T_SPEC)
    sp = spectrum(run, T_SPEC)
    if sr is not None and sp is not None:
        k, e = sp["k"], sp["E"]
        kk, kr = float(sr["k_kernel"]), float(sr["k_resolution"])
        ik = np.argmin(np.abs(k - kk))
        record(name, "E(k_kern)(14)", float(e[ik]), f"E at the shell k = {k[ik]:g}")
        record(name, "E(k_kern)/E(2)(14)", float(e[ik] / e[np.argmin(np.abs(k - 2))]),
               "kernel-scale energy relative to the TGV shell")
        record(name, "eps_spectral_resolved(14)", float(sr["dissipation_spectral_resolved"]),
               "2 nu sum k^2 E dk, k <= k_res")
        # log-log slope of E over [2, k_kern] (inertial or deficit range at this N)
        m2 = (k >= 2) & (k <= kk + 1e-9)
        if m2.sum() >= 2:
            record(name, "spectral_slope_[2,k_kern](14)",
                   float(np.polyfit(np.log(k[m2]), np.log(e[m2]), 1)[0]))
        m3 = (k >= kk) & (k <= kr + 1e-9)
        if m3.sum() >= 2:
            record(name, "spectral_slope_[k_kern,k_res](14)",
                   float(np.polyfit(np.log(k[m3]), np.log(e[m3]), 1)[0]))
    # Correlation of |τ_SFS| and ω² on the slice x = π at t = 14.
    for tq in (5.0, T_SPEC):
        sl = slice_pair(run, tq)
        if sl is not None:
            w2, tau = sl
            record(name, f"slice_corr_tau_omega2({tq:g})",
                   float(np.corrcoef(w2.ravel(), tau.ravel())[0, 1]), "Pearson, grid plane x = π")
    for tq in (5.0, T_SPEC):
        jt = joint(run, tq)
        if jt is not None:
            record(name, f"joint_corr_tau_omega2({tq:g})", joint_correlation(jt),
                   "Pearson over particles, from the (τ*, ω²*) histogram bin centres")
    if snap is not None:
        for tq in (5.0,):
            j = np.where(np.abs(snap["t"] - tq) < 1e-6)[0]
            if len(j):
                record(name, f"tau_sfs_mean/e_v({tq:g})",
                       float(snap["tau_sfs_mean"][j[0]]) / value_at(t, ev, tq))


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


def save(fig, docs, name, colors=128):
    path = os.path.join(docs, "figures", name)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    try:  # a 128-colour palette keeps the figures small enough for the repository
        from PIL import Image
        Image.open(path).convert("RGB").quantize(colors=colors).save(path, optimize=True)
    except ImportError:
        pass
    print("wrote", os.path.relpath(path, ROOT), f"{os.path.getsize(path) // 1024} KB")


def plot_energy(runs, ref, docs):
    fig, axes = plt.subplots(2, 3, figsize=(15, 8.5))
    for g, (title, names) in enumerate(GROUPS):
        ax, bx = axes[0, g], axes[1, g]
        if ref is not None:
            ax.plot(ref["t"], ref["e_v"], color="k", lw=1, label="DNS Re 5000 (guide)")
            bx.plot(ref["t"], ref["eps"], color="k", lw=1, label="DNS Re 5000 (guide)")
        for n in names:
            if n not in runs:
                continue
            r = runs[n]
            st = STYLE[n]
            ax.plot(r["ts"]["t"], r["ts"]["e_v"], label=TGV_RUNS[n][0], **st)
            bx.plot(r["ts"]["t"], r["ts"]["dissipation"], color=st["color"], lw=0.5, alpha=0.35)
            if "eps_smooth" in r:
                bx.plot(*r["eps_smooth"], label=TGV_RUNS[n][0], **st)
            if r["snap"] is not None:
                bx.plot(r["snap"]["t"], r["snap"]["dissipation_vorticity"], "o", ms=3,
                        color=st["color"])
        ax.set_title("e_v(t): " + title, fontsize=10)
        bx.set_title("ε(t): -de_v/dt (thin: 0.2 trailing window, thick: 1.0 centred), dots ν⟨ω²⟩",
                     fontsize=9)
        ax.set_xlim(0, 15)
        bx.set_xlim(0, 15)
        ax.set_ylim(0, 0.13)
        bx.set_ylim(0, 0.03)
        ax.set_xlabel("t")
        bx.set_xlabel("t")
        ax.legend(fontsize=7)
        bx.legend(fontsize=7)
        ax.grid(alpha=0.3)
        bx.grid(alpha=0.3)
    fig.tight_layout()
    save(fig, docs, "validation_energy_dissipation.png")


def plot_decay(runs, ref, docs):
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    if ref is not None:
        ax.loglog(ref["t"][1:], ref["e_v"][1:], color="k", lw=1, label="DNS Re 5000 (guide)")
    for n in ("case8_n24", "case8_n32", "case8_n48", "case1_n32", "case12_n32", "case20_n32"):
        if n in runs:
            ax.loglog(runs[n]["ts"]["t"][1:], runs[n]["ts"]["e_v"][1:], label=TGV_RUNS[n][0],
                      **STYLE[n])
    tt = np.array([9.0, 15.0])
    ax.loglog(tt, 0.06 * (tt / 9.0) ** -1.2, color="gray", ls="-.", label="t^-1.2 (thesis)")
    ax.set_xlim(1, 16)
    ax.set_ylim(5e-3, 0.2)
    ax.set_xlabel("t")
    ax.set_ylabel("e_v")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    save(fig, docs, "validation_decay_loglog.png")


def plot_spectra(runs, docs):
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8))
    for g, (title, names) in enumerate(GROUPS):
        ax = axes[g]
        for n in names:
            if n not in runs:
                continue
            sp = spectrum(runs[n], T_SPEC)
            sr = spectrum_row(runs[n], T_SPEC)
            if sp is None or sr is None:
                continue
            st = STYLE[n]
            m = sp["k"] > 0
            ax.loglog(sp["k_Lc"][m], sp["E_over_ev_Lc"][m], label=TGV_RUNS[n][0], **st)
            lc = sr["L_c"]
            ax.axvline(sr["k_kernel"] * lc, color=st["color"], ls=st["ls"], lw=0.7, alpha=0.6)
        kk = np.array([3.0, 30.0])
        ax.loglog(kk, 0.3 * (kk / 3) ** (-5 / 3), color="gray", ls="-.", label="k^-5/3")
        ax.loglog(kk, 0.3 * (kk / 3) ** (-4.0), color="gray", ls=":", label="k^-4")
        ax.set_ylim(1e-6, 3)
        ax.set_xlabel("k L_c  (L_c = π)")
        ax.set_ylabel("E(k) / (e_v L_c)")
        ax.set_title(f"E(k) at t = {T_SPEC:g}: {title}\nthin vertical lines: k_kern = 2π/D_K",
                     fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    save(fig, docs, "validation_spectra_t14.png")


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


def plot_spectra_time(runs, ref, docs):
    names = [n for n in ("case1_n32", "case8_n24", "case8_n32", "case8_n48", "case8_n48_t5")
             if n in runs]
    if not names:
        return
    fig, axes = plt.subplots(1, len(names) + 1, figsize=(4.2 * (len(names) + 1), 4))
    for c, n in enumerate(names):
        ax = axes[c]
        for tq, col in zip((0, 2, 5, 9, 14), plt.cm.viridis(np.linspace(0, 0.9, 5))):
            sp = spectrum(runs[n], tq)
            if sp is not None:
                m = sp["k"] > 0
                ax.loglog(sp["k"][m], sp["E"][m], color=col, label=f"t = {tq}")
        sr = spectrum_row(runs[n], 0.0)
        if sr is not None:
            ax.axvline(sr["k_kernel"], color="k", ls="--", lw=0.8, label="k_kern")
            ax.axvline(sr["k_resolution"], color="k", ls=":", lw=0.8, label="k_res")
        ax.set_ylim(1e-7, 0.2)
        ax.set_xlabel("k")
        ax.set_ylabel("E(k)")
        ax.set_title(TGV_RUNS[n][0], fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3, which="both")
    ax = axes[-1]
    if ref is not None:
        ax.plot(ref["t"], ref["e_v"], color="k", lw=1, label="DNS Re 5000 e_v (all scales)")
    for n in TGV_RUNS:
        if n in runs:
            ls = large_scale_energy(runs[n])
            if ls is not None:
                ax.plot(ls[:, 0], ls[:, 1], marker=".", label=TGV_RUNS[n][0], **STYLE[n])
    ax.set_xlabel("t")
    ax.set_title("energy of the shells k <= 2 (TGV mode |k| = √3 and larger)", fontsize=9)
    ax.set_xlim(0, 15)
    ax.set_ylim(0, 0.13)
    ax.legend(fontsize=6)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save(fig, docs, "validation_spectra_history.png")


def plot_slices(runs, docs):
    names = [n for n in ("case8_n24", "case8_n32", "case8_n48", "case8_n48_t5", "case1_n32",
                         "case12_n32") if n in runs and slice_pair(runs[n], 5.0) is not None]
    if not names:
        return
    times = (5.0, T_SPEC)
    fig, axes = plt.subplots(4, len(names), figsize=(2.2 * len(names), 8.8), squeeze=False)
    for c, n in enumerate(names):
        for b, tq in enumerate(times):
            pair = slice_pair(runs[n], tq)
            if pair is None:
                axes[2 * b, c].axis("off")
                axes[2 * b + 1, c].axis("off")
                continue
            for r, (f, lab) in enumerate(((pair[0], "ω²"), (pair[1], "|τ_SFS|"))):
                ax = axes[2 * b + r, c]
                im = ax.imshow(f, origin="lower", extent=(0, 2 * math.pi, 0, 2 * math.pi),
                               cmap="inferno", vmin=0, vmax=np.percentile(f, 99.5))
                ax.set_title(f"{TGV_RUNS[n][0]}\nt = {tq:g}, {lab}, max {f.max():.3g}", fontsize=7)
                ax.set_xticks([])
                ax.set_yticks([])
                fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02).ax.tick_params(labelsize=6)
    fig.suptitle("Slices x = π, axes y, z ∈ [0, 2π]\ncolours to the 99.5th percentile", fontsize=8)
    fig.tight_layout()
    save(fig, docs, "validation_slices.png", colors=48)


def plot_joint(runs, docs):
    names = [n for n in ("case8_n24", "case8_n32", "case8_n48", "case8_n48_t5", "case1_n32",
                         "case12_n32") if n in runs and joint(runs[n], 5.0) is not None]
    if not names:
        return
    fig, axes = plt.subplots(2, len(names), figsize=(3.0 * len(names), 6.0), squeeze=False)
    for c, n in enumerate(names):
        for r, tq in enumerate((5.0, T_SPEC)):
            ax = axes[r, c]
            j = joint(runs[n], tq)
            if j is None:
                ax.axis("off")
                continue
            tb = np.unique(np.concatenate([j["tau_lo"], j["tau_hi"]]))
            ob = np.unique(np.concatenate([j["omega2_lo"], j["omega2_hi"]]))
            h = np.zeros((len(ob) - 1, len(tb) - 1))
            for a, b, cnt in zip(j["tau_lo"], j["omega2_lo"], j["count"]):
                h[np.searchsorted(ob, b), np.searchsorted(tb, a)] += cnt
            ax.pcolormesh(tb, ob, np.log10(np.where(h > 0, h, np.nan)), cmap="viridis")
            ax.set_xlabel("τ_SFS / max", fontsize=8)
            ax.set_ylabel("ω² / max", fontsize=8)
            ax.set_title(f"{TGV_RUNS[n][0]}, t = {tq:g}\nlog10 count, r = {joint_correlation(j):.2f}",
                         fontsize=8)
    fig.tight_layout()
    save(fig, docs, "validation_joint_tau_omega2.png")


def kolmogorov(runs_dir, docs):
    name = "kolmogorov_n48"
    r = load_run(runs_dir, name)
    if r is None:
        return
    ts = r["ts"]
    t = ts["t"]
    if r["wall"]:
        record(name, "wall_seconds", round(r["wall"]["wall_seconds"], 1))
        record(name, "exit_code", r["wall"]["exit_code"])
    t_end = float(t[-1])
    record(name, "t_end", t_end)
    record(name, "steps", int(ts["step"][-1]))
    t0 = record(name, "average_from", round(t_end / 2, 3), "statistics over [t_end/2, t_end]")
    m = t >= t0
    cm = 1e4  # m²/s³ -> cm²/s³
    inj = record(name, "eps_inj_cm2s3", float(np.mean(ts["energy_injection"][m])) * cm)
    film = record(name, "eps_film_cm2s3", float(np.mean(ts["film_dissipation"][m])) * cm)
    record(name, "u_rms", float(np.mean(ts["u_rms"][m])), "m/s, target 0.11")
    snap = r["snap"]
    ev = math.nan
    if snap is not None:
        s = snap["t"] >= t0
        ev = record(name, "eps_v_cm2s3", float(np.mean(snap["dissipation_vorticity"][s])) * cm,
                    "nu <omega^2> on the grid, snapshots")
        record(name, "budget_residual_cm2s3", inj - ev - film, "eps_inj - eps_v - eps_film")
    record(name, "max_density_deviation_max", float(np.nanmax(ts["max_density_deviation"])))
    # principal-direction angle statistics, averaged over the snapshots in [t0, t_end]
    d = os.path.join(r["dir"], "stats")
    hist = None
    used = 0
    for f in sorted(os.listdir(d)) if os.path.isdir(d) else []:
        if f.startswith("alignment_t") and float(f[len("alignment_t"):-4]) >= t0:
            a = read_csv(os.path.join(d, f))
            used += 1
            hist = a if hist is None else {**hist, "count": hist["count"] + a["count"]}
    fig, axes = plt.subplots(1, 3 if hist is not None else 2, figsize=(14, 4))
    ax = axes[0]
    ax.plot(t, ts["energy_injection"] * cm, label="ε_inj = ⟨χ sin(k_y y) v_x⟩")
    ax.plot(t, ts["film_dissipation"] * cm, label="ε_film = μ⟨v²⟩")
    if snap is not None:
        ax.plot(snap["t"], snap["dissipation_vorticity"] * cm, "o-", label="ε_v = ν⟨ω²⟩")
    for y, lab in ((140, "experiment ε_inj"), (288.6, "thesis ε_inj (336²)")):
        ax.axhline(y, color="gray", ls=":", lw=1)
        ax.text(t_end, y, lab, fontsize=7, va="bottom", ha="right")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("cm²/s³")
    ax.set_yscale("log")
    ax.legend(fontsize=7)
    ax.set_title("Kolmogorov flow, 48², L = 12 mm, D_K = 2 mm, χ = 1.8: budget", fontsize=9)
    ax = axes[1]
    times = sorted(set(float(x) for x in r["spec_index"]["t"] if x >= t0)) \
        if r["spec_index"] is not None else []
    for tq in times[::4]:
        sp = spectrum(r, tq)
        if sp is not None:
            mm = sp["k"] > 0
            ax.loglog(sp["k"][mm], sp["E"][mm], lw=0.8, label=f"t = {tq:g} s")
    sr = spectrum_row(r, t_end) if r["spec_index"] is not None else None
    if sr is not None:
        ax.axvline(sr["k_kernel"], color="k", ls="--", lw=0.8, label="k_kern = 2π/D_K")
        ax.axvline(sr["k_resolution"], color="k", ls=":", lw=0.8, label="k_res = π/Δl")
        ax.axvline(2 * math.pi * 2 / (0.042 * 2 / 7), color="gray", ls="-.", lw=0.8,
                   label="forcing k_y")
    ax.set_xlabel("k [1/m]")
    ax.set_ylabel("E(k) [m³/s²]")
    ax.legend(fontsize=6)
    ax.set_title("E(k)", fontsize=9)
    if hist is not None:
        frac = hist["count"] / hist["count"].sum()
        lo, hi = hist["gamma_lo"], hist["gamma_hi"]
        ax = axes[2]
        ax.bar(np.degrees(lo), frac * 100, width=np.degrees(hi - lo), align="edge",
               edgecolor="k")
        ax.set_xlabel("γ [deg] between t_I and v")
        ax.set_ylabel("% of particles with τ*/max > 0.1")
        ax.set_title("principal-direction angle, snapshots t ≥ %.2f s" % t0, fontsize=9)
        record(name, "gamma_snapshots", used, "alignment histograms summed")
        record(name, "gamma_bins", len(frac))
        record(name, "gamma_first_bin_percent", float(frac[0] * 100),
               f"γ in [0, {math.degrees(hi[0]):.0f}°]")
        record(name, "gamma_last_bin_percent", float(frac[-1] * 100),
               f"γ in [{math.degrees(lo[-1]):.0f}°, 90°]")
        below = float(frac[hi <= math.pi / 4 + 1e-9].sum() * 100)
        record(name, "gamma_cumulative_0_45_percent", below)
        record(name, "gamma_cumulative_45_90_percent", 100 - below)
    fig.tight_layout()
    save(fig, docs, "validation_kolmogorov.png")


TABLE = [("wall [s]", "wall_seconds", "{:.0f}"), ("steps", "steps", "{:d}"),
         ("t reached", "t_end", "{:g}"),
         ("e_v(5)/e_v(0)", "e_v(5)/e_v(0)", "{:.3f}"), ("e_v(14)", "e_v(14)", "{:.4f}"),
         ("E(k<=2) at 5 / 9 / 14", ("energy_k<=2(5)", "energy_k<=2(9)", "energy_k<=2(14)"),
          "{:.4f}"),
         ("noise share k>k_kern at 5 / 14", ("energy_fraction_k>k_kern(5)",
                                             "energy_fraction_k>k_kern(14)"), "{:.2f}"),
         ("t of max ε (t>=3)", "t_eps_peak", "{:.1f}"), ("max ε (t>=3)", "eps_peak", "{:.4f}"),
         ("k_SPH / k_kern at 5 / 14", ("k_SPH/k_kernel(5)", "k_SPH/k_kernel(14)"), "{:.2f}"),
         ("max ρ dev", "max_density_deviation_max", "{:.3f}"),
         ("r(τ,ω²) slice 5 / 14", ("slice_corr_tau_omega2(5)", "slice_corr_tau_omega2(14)"),
          "{:.2f}"),
         ("⟨τ⟩/e_v at 5 / 14", ("tau_sfs_mean/e_v(5)", "tau_sfs_mean/e_v(14)"), "{:.2f}")]


def plot_tvf(runs, ref, docs):
    """e_v(t) and the smoothed ε(t) of the TVF runs against the DNS (the thesis-model
    counterparts too when their run directories are present)."""
    names = [n for pair in TVF_PAIRS for n in pair if n in runs]
    if not any(n.startswith("tvf_") for n in names):
        return
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.5))
    if ref is not None:
        ax.plot(ref["t"], ref["e_v"], color="k", lw=1, label="DNS Re 5000 (guide)")
        bx.plot(ref["t"], ref["eps"], color="k", lw=1, label="DNS Re 5000 (guide)")
    for n in names:
        r, st = runs[n], dict(STYLE[n])
        if not n.startswith("tvf_"):
            st.update(ls=":", lw=1)
        ax.plot(r["ts"]["t"], r["ts"]["e_v"], label=TGV_RUNS[n][0], **st)
        if "eps_smooth" in r:
            bx.plot(*r["eps_smooth"], label=TGV_RUNS[n][0], **st)
    ax.set_title("e_v(t), 32³: transport-velocity scheme (dotted: thesis model if present)",
                 fontsize=9)
    bx.set_title("ε(t) = -de_v/dt, 1.0 centred window", fontsize=9)
    for a, top in ((ax, 0.13), (bx, 0.03)):
        a.set_xlim(0, 15)
        a.set_ylim(0, top)
        a.set_xlabel("t")
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    save(fig, docs, "validation_tvf.png")


def read_kept_rows(path, loaded):
    """The rows of an earlier validation_findings.csv whose run is not among `loaded` (--merge)."""
    kept = []
    if not os.path.exists(path):
        return kept
    with open(path, newline="") as f:
        for run, quantity, value, note in list(csv.reader(f))[1:]:
            if run in loaded or run == "campaign":
                continue
            try:
                value = float(value)
            except ValueError:
                pass
            kept.append((run, quantity, value, note))
    return kept


def print_table(runs):
    """The per-run numbers of the CSV as a markdown table (pasted into docs/validation.md)."""
    look = {(r, q): v for r, q, v, _ in rows}

    def fmt(run, key, f):
        keys = key if isinstance(key, tuple) else (key,)
        out = []
        for k in keys:
            v = look.get((run, k))
            out.append("–" if v is None or (isinstance(v, float) and math.isnan(v))
                       else f.format(int(v) if "d" in f else v))
        return " / ".join(out)

    print("| run | " + " | ".join(h for h, _, _ in TABLE) + " |")
    print("|---" * (len(TABLE) + 1) + "|")
    recorded = {r for r, _, _, _ in rows}
    for n in list(TGV_RUNS) + ["dns_re5000"]:
        if n in runs or n in recorded:
            label = TGV_RUNS[n][0] if n in TGV_RUNS else "DNS Re 5000"
            print(f"| {label} | " + " | ".join(fmt(n, k, f) for _, k, f in TABLE) + " |")


def main():
    global T_SPEC
    p = argparse.ArgumentParser()
    p.add_argument("--runs", default=os.path.join(ROOT, "runs", "validation"))
    p.add_argument("--docs", default=os.path.join(ROOT, "docs"))
    p.add_argument("--t-spectra", type=float, default=T_SPEC,
                   help="time of spectra, slices and statistics (14; smaller only for tests)")
    p.add_argument("--merge", action="store_true",
                   help="keep the CSV rows of runs not found in --runs and write only the figures "
                        "that need none of the missing runs (validation_tvf.png)")
    a = p.parse_args()
    T_SPEC = a.t_spectra
    os.makedirs(os.path.join(a.docs, "figures"), exist_ok=True)
    ref = load_reference()
    if ref is not None:
        i = np.argmax(ref["eps"])
        record("dns_re5000", "eps_peak", float(ref["eps"][i]), "Dairay et al. 2017, 1280³")
        record("dns_re5000", "t_eps_peak", float(ref["t"][i]))
        for tq in (5.0, 9.0, 14.0):
            record("dns_re5000", f"e_v({tq:g})", value_at(ref["t"], ref["e_v"], tq))
        record("dns_re5000", "e_v(5)/e_v(0)", value_at(ref["t"], ref["e_v"], 5.0) / ref["e_v"][0])
        m = (ref["t"] >= 10.0) & (ref["t"] <= 15.0)
        record("dns_re5000", "decay_exponent",
               float(-np.polyfit(np.log(ref["t"][m]), np.log(ref["e_v"][m]), 1)[0]),
               "fit e_v ~ t^-a over [10, 15]")
    runs = {}
    for n in TGV_RUNS:
        r = load_run(a.runs, n)
        if r is not None:
            runs[n] = r
            tgv_numbers(r, ref)
    missing = [n for n in TGV_RUNS if n not in runs]
    if missing:
        print("not found (not run):", ", ".join(missing))
    out = os.path.join(a.docs, "validation_findings.csv")
    if a.merge:
        rows.extend(read_kept_rows(out, set(runs) | {"dns_re5000"}))
    else:
        plot_energy(runs, ref, a.docs)
        plot_decay(runs, ref, a.docs)
        plot_spectra(runs, a.docs)
        plot_spectra_time(runs, ref, a.docs)
        plot_slices(runs, a.docs)
        plot_joint(runs, a.docs)
        kolmogorov(a.runs, a.docs)
    plot_tvf(runs, ref, a.docs)
    walls = [v for r, q, v, _ in rows if q == "wall_seconds"]
    record("campaign", "runs_completed", len(walls))
    record("campaign", "total_wall_seconds", round(float(sum(walls)), 0), "sum over runs")
    print_table(runs)
    with open(out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["run", "quantity", "value", "note"])
        for run, q, v, note in rows:
            w.writerow([run, q, f"{v:.6g}" if isinstance(v, float) else v, note])
    print("wrote", os.path.relpath(out, ROOT), len(rows), "rows")
    return 0


if __name__ == "__main__":
    sys.exit(main())
