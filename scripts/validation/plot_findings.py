#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Figures and numbers of the SPEC §7 findings from the runs of run_findings.py.

    /usr/bin/python3 scripts/validation/plot_findings.py [--runs runs/validation] [--docs docs]

Reads RUNS/NAME/{timeseries.csv, stats/, spectra/, slices/, wall.json} for every run that
exists (missing runs are left out of the figures and listed), writes
DOCS/figures/validation_*.png and DOCS/validation_findings.csv (columns run, quantity, value,
note): every number docs/validation.md quotes. Needs python3, numpy and matplotlib only.
The runs and their files are read by findings_runs.py, the numbers taken by findings_numbers.py;
this script draws the figures and writes the CSV.
"""

import argparse
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import findings_runs  # noqa: E402
from findings_numbers import dns_numbers, print_table, read_kept_rows, tgv_numbers  # noqa: E402
from findings_runs import (ROOT, TGV_RUNS, TVF_PAIRS, joint, joint_correlation,  # noqa: E402
                           large_scale_energy, load_reference, load_run, read_csv, record, rows,
                           slice_pair, spectrum, spectrum_row)

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
            sp = spectrum(runs[n], findings_runs.T_SPEC)
            sr = spectrum_row(runs[n], findings_runs.T_SPEC)
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
        ax.set_title(f"E(k) at t = {findings_runs.T_SPEC:g}: {title}\n"
                     "thin vertical lines: k_kern = 2π/D_K", fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    save(fig, docs, "validation_spectra_t14.png")


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
    times = (5.0, findings_runs.T_SPEC)
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
        for r, tq in enumerate((5.0, findings_runs.T_SPEC)):
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


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--runs", default=os.path.join(ROOT, "runs", "validation"))
    p.add_argument("--docs", default=os.path.join(ROOT, "docs"))
    p.add_argument("--t-spectra", type=float, default=findings_runs.T_SPEC,
                   help="time of spectra, slices and statistics (14; smaller only for tests)")
    p.add_argument("--merge", action="store_true",
                   help="keep the CSV rows of runs not found in --runs and write only the figures "
                        "that need none of the missing runs (validation_tvf.png)")
    a = p.parse_args()
    findings_runs.T_SPEC = a.t_spectra
    os.makedirs(os.path.join(a.docs, "figures"), exist_ok=True)
    ref = load_reference()
    if ref is not None:
        dns_numbers(ref)
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
