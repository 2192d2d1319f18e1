# SPDX-License-Identifier: GPL-3.0-or-later
"""The numbers of the SPEC §7 findings that docs/validation.md quotes, recorded as rows of
DOCS/validation_findings.csv (findings_runs.record), and their markdown table; plot_findings.py
writes them."""

import csv
import math
import os

import numpy as np

import findings_runs
from findings_runs import (TGV_RUNS, joint, joint_correlation, large_scale_energy, local_maxima,
                           record, rows, slice_pair, smooth_dissipation, spectrum, spectrum_row,
                           value_at)


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
        record(name, "eps_smooth(14)",
               value_at(g[np.isfinite(eg)], eg[np.isfinite(eg)], findings_runs.T_SPEC),
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
        j = np.where(np.abs(snap["t"] - findings_runs.T_SPEC) < 1e-6)[0]
        if len(j):
            j = j[0]
            record(name, "eps_vorticity(14)", float(snap["dissipation_vorticity"][j]),
                   "nu <omega^2> on the grid")
            record(name, "eps_spectral(14)", float(snap["dissipation_spectral"][j]),
                   "2 nu sum k^2 E dk, all shells")
            record(name, "eps_history(14)", value_at(t, eps, findings_runs.T_SPEC), "-de_v/dt")
            record(name, "tau_sfs_mean(14)", float(snap["tau_sfs_mean"][j]))
            record(name, "tau_sfs_max(14)", float(snap["tau_sfs_max"][j]))
            record(name, "tau_sfs_mean/e_v(14)",
                   float(snap["tau_sfs_mean"][j]) / value_at(t, ev, findings_runs.T_SPEC))
        asec = snap["analysis_seconds"]
        record(name, "analysis_seconds_total", round(float(np.nansum(asec)), 1))
    sr0 = spectrum_row(run, 0.0)
    if sr0 is not None:
        kk, kr = float(sr0["k_kernel"]), float(sr0["k_resolution"])
        record(name, "k_kernel", kk, "2π/D_K")
        record(name, "k_resolution", kr, "π/Δl")
        ls = large_scale_energy(run)
        for tq in (0.0, 5.0, 9.0, findings_runs.T_SPEC):
            i = np.where(np.abs(ls[:, 0] - tq) < 1e-6)[0] if ls is not None else []
            if len(i):
                record(name, f"energy_k<=2({tq:g})", float(ls[i[0], 1]),
                       "energy of the TGV shell |k| = √3 and larger scales")
        for tq in (0.0, 2.0, 5.0, 9.0, findings_runs.T_SPEC):
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
    sr = spectrum_row(run, findings_runs.T_SPEC)
    sp = spectrum(run, findings_runs.T_SPEC)
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
    for tq in (5.0, findings_runs.T_SPEC):
        sl = slice_pair(run, tq)
        if sl is not None:
            w2, tau = sl
            record(name, f"slice_corr_tau_omega2({tq:g})",
                   float(np.corrcoef(w2.ravel(), tau.ravel())[0, 1]), "Pearson, grid plane x = π")
    for tq in (5.0, findings_runs.T_SPEC):
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




def dns_numbers(ref):
    """The DNS' own numbers (run dns_re5000), for the table beside the runs'."""
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


