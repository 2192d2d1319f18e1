// SPDX-License-Identifier: GPL-3.0-or-later
// The plots of the selected run: e_v(t), ε(t), E(k) and the sub-filter stress statistics, with
// the run's reference curve and the runs compared with it.

import { api } from './api.js';
import {
  plottingAvailable, formatNumber, energyChart, dissipationChart, spectrumChart, statisticsChart,
  budgetChart, rmsChart, spectrumData, drawJointHistogram, drawAlignmentHistogram,
} from './charts.js';
import { EXPERIMENT, isForced, budgetPoints, budgetAverages, budgetCaption } from './budget.js';
import { $, app, setText, showStatus, isCancelled, errorText, columnOf } from './state.js';
import { loadComparedRun, spectrumView, redrawWith } from './compare.js';

const REDRAW_MS = 250;
redrawWith(scheduleRedraw);

export function ensureCharts() {
  if (app.charts || !plottingAvailable()) return;
  app.charts = {
    energy: energyChart($('chart-energy')),
    dissipation: dissipationChart($('chart-dissipation')),
    spectrum: spectrumChart($('chart-spectrum')),
    stats: statisticsChart($('chart-stats')),
    budget: budgetChart($('chart-budget')),
    urms: rmsChart($('chart-urms')),
  };
}

export function scheduleRedraw() {
  if (app.redrawTimer) return;
  app.redrawTimer = setTimeout(() => {
    app.redrawTimer = null;
    redraw();
  }, REDRAW_MS);
}

/** Two sets of series on one increasing time axis ({x, ys}), null where a set has no value. */
function mergeOnTime(a, b) {
  const x = [];
  const ys = [...a.ys, ...b.ys].map(() => []);
  let i = 0;
  let j = 0;
  while (i < a.x.length || j < b.x.length) {
    const takeA = j >= b.x.length || (i < a.x.length && a.x[i] <= b.x[j]);
    x.push(takeA ? a.x[i] : b.x[j]);
    a.ys.forEach((column, k) => ys[k].push(takeA ? column[i] : null));
    b.ys.forEach((column, k) => ys[a.ys.length + k].push(takeA ? null : column[j]));
    if (takeA) i++;
    else j++;
  }
  return { x, ys };
}

/** Overlays (or removes) a run's time series on the plots, and its spectrum at the compare
 *  slider's time (compare.js). */
export async function toggleCompared(id, on) {
  if (!on) {
    app.compared.delete(id);
    scheduleRedraw();
    return;
  }
  const run = app.runs.find((r) => r.id === id);
  const entry = { label: run?.name || id, time: [], energy: [], dissipation: [] };
  app.compared.set(id, entry);
  try {
    const [series, detail] = await Promise.all([api.timeseries(id), api.run(id)]);
    const col = columnOf(series);
    Object.assign(entry, { time: col('time'), energy: col('kinetic_energy'), dissipation: col('dissipation') });
    await loadComparedRun(id, entry, detail);
  } catch (e) {
    showStatus('control-status', `Could not load ${entry.label} for comparison: ${errorText(e)}`, 'error');
  }
  scheduleRedraw();
}

/** The runs compared with the selected one (not itself), in the order they were ticked. */
function comparedRuns() {
  return [...app.compared.entries()].filter(([id]) => id !== app.selectedId).map(([, r]) => r);
}

/** The compared runs' columns merged onto a plot's {x, ys} (one more series per run). */
function withCompared(rows, column) {
  let merged = rows;
  for (const c of comparedRuns()) {
    const other = column(c);
    merged = mergeOnTime(merged, { x: other.x, ys: [other.y] });
  }
  return merged;
}

/** The reference's points at times up to `horizon`. */
function clipReference(ref, horizon) {
  const n = ref.time.findIndex((t) => t > horizon);
  if (n < 0) return ref;
  return { ...ref, time: ref.time.slice(0, n), energy: ref.energy.slice(0, n), dissipation: ref.dissipation.slice(0, n) };
}

function redraw() {
  const c = app.charts;
  const samples = app.samples;
  const last = samples[samples.length - 1];
  const refNote = app.reference ? `; dashed: ${app.reference.label}` : (app.referenceWhy ? '; no reference' : '');
  setText('cap-energy', (last ? `eᵥ = ${formatNumber(last.kinetic_energy)} m²/s² at t = ${formatNumber(last.time)} s (${samples.length} samples)` : 'no samples yet') + refNote);
  $('cap-energy').title = app.reference ? app.reference.source : (app.referenceWhy ?? '');
  const lastEps = [...app.analysis].reverse().find((a) => a.spectral !== null || a.vorticity !== null);
  setText('cap-dissipation', last ? `−deᵥ/dt = ${formatNumber(last.dissipation)}` +
    `${lastEps ? `, spectral ${formatNumber(lastEps.spectral ?? lastEps.vorticity)}` : ''} m²/s³` : '');
  drawJointHistogram($('hist-joint'), app.latestStatistics?.joint);
  drawAlignmentHistogram($('hist-alignment'), app.latestStatistics ? app.latestStatistics.alignment ?? null : undefined);
  if (!c) return;

  // The reference up to twice the latest time of the plotted runs (all of it before the first
  // sample): a long run's reference (time.end = 500) does not squeeze its first seconds into
  // the plot's left edge, and the curve still shows where the run is heading.
  const latest = Math.max(last ? last.time : 0, ...comparedRuns().map((r) => r.time?.[r.time.length - 1] ?? 0));
  const horizon = latest > 0 ? 2 * latest : Infinity;
  refreshReferenceSpan(horizon);
  const ref = app.reference ? clipReference(app.reference, horizon) : null;
  const refRows = ref ? { x: ref.time, ys: [ref.energy] } : { x: [], ys: [[]] };
  // E_res beside e_v: the energy e_v hides behind the particle-scale part (GET resolved).
  const res = app.resolved?.samples ?? [];
  const resRows = {
    x: res.map((r) => r.t),
    ys: [res.map((r) => r.resolved_energy),
      res.map((r) => (r.reference_resolved_energy > 1e-12 * r.reference_energy ? r.reference_resolved_energy : null))],
  };
  const energy = withCompared(
    mergeOnTime(mergeOnTime({ x: samples.map((s) => s.time), ys: [samples.map((s) => s.kinetic_energy)] }, refRows), resRows),
    (r) => ({ x: r.time, y: r.energy }));
  const labels = comparedRuns().map((r) => r.label);
  for (const chart of [c.energy, c.dissipation]) chart.setExtraSeries(labels);
  c.energy.setData(energy.x, energy.ys);
  $('chart-energy').dataset.referencePoints = String(ref ? ref.time.length : 0);
  $('chart-energy').dataset.resolvedPoints = String(res.length);
  $('chart-energy').dataset.referenceEnd = String(ref && ref.time.length ? ref.time[ref.time.length - 1] : 0);
  $('chart-energy').dataset.latest = String(latest);

  // ε: the per-step series, the sparse analysis estimates and the reference on one time axis.
  const estimates = mergeOnTime(
    { x: samples.map((s) => s.time), ys: [samples.map((s) => s.dissipation)] },
    { x: app.analysis.map((a) => a.time),
      ys: [app.analysis.map((a) => a.spectral ?? null), app.analysis.map((a) => a.vorticity ?? null)] });
  const eps = withCompared(mergeOnTime(estimates,
    ref ? { x: ref.time, ys: [ref.dissipation] } : { x: [], ys: [[]] }),
  (r) => ({ x: r.time, y: r.dissipation }));
  c.dissipation.setData(eps.x, eps.ys);

  // The spectra at the compare slider's time (compare.js): the selected run's (its latest, live,
  // with nothing compared) and each compared run's nearest; none yet (a run just selected)
  // empties the plot.
  const view = spectrumView();
  const s = view.own;
  const hasSpectrum = s && Array.isArray(s.k) && Array.isArray(s.energy);
  // The reference's E(k), dashed (GET resolved): the server has it at the run's latest time
  // only, so not at another time on the slider.
  // Shells the reference leaves empty (round-off, 10⁻³⁰ of its peak) are not drawn: they
  // would stretch the log axis over tens of decades.
  const refSpectrum = hasSpectrum && view.referenceShown ? app.resolved?.reference_spectrum : null;
  const refPeak = refSpectrum ? Math.max(...refSpectrum.energy) : 0;
  const refKeep = refSpectrum
    ? refSpectrum.k.map((k, i) => i).filter((i) => refSpectrum.k[i] > 0 && refSpectrum.energy[i] > 1e-12 * refPeak)
    : [];
  const own = mergeOnTime(hasSpectrum ? spectrumData(s.k, s.energy) : spectrumData([], []),
    { x: refKeep.map((i) => refSpectrum.k[i]), ys: [refKeep.map((i) => refSpectrum.energy[i])] });
  $('chart-spectrum').dataset.referencePoints = String(refKeep.length);
  c.spectrum.setExtraSeries(view.compared.map((r) => r.label));
  let d = own;
  for (const r of view.compared) {
    const keep = r.k.map((kk, i) => i).filter((i) => r.k[i] > 0);
    d = mergeOnTime(d, { x: keep.map((i) => r.k[i]), ys: [keep.map((i) => (r.energy[i] > 0 ? r.energy[i] : null))] });
  }
  c.spectrum.setData(d.x, d.ys);
  // The run's wavenumbers do not change with time: the latest spectrum's.
  const marks = app.spectrum;
  c.spectrum.setMarkers(hasSpectrum && marks ? [
    { x: marks.kernel_wavenumber, label: 'k_kern = 2π/D_K', colour: '#b22222', row: 0 },
    { x: marks.resolution_wavenumber, label: 'k_res = π/Δl', colour: '#555555', row: 1 },
  ] : []);
  c.stats.setData(app.stats.map((p) => p.time), [app.stats.map((p) => p.max), app.stats.map((p) => p.mean)]);
  drawBudget(c, samples);
}

/** A forced flow shows its budget and u_rms in place of −deᵥ/dt, which there is no dissipation. */
function drawBudget(c, samples) {
  const forced = isForced(samples);
  $('fig-dissipation').hidden = forced;
  $('fig-budget').hidden = !forced;
  $('fig-urms').hidden = !forced;
  if (!forced) return;
  const points = budgetPoints(samples, app.analysis);
  const change = samples.map((s) => (Number.isFinite(s.dissipation) ? -s.dissipation : null));
  const budget = mergeOnTime(
    { x: samples.map((s) => s.time),
      ys: [samples.map((s) => s.energy_injection), samples.map((s) => s.film_dissipation), change] },
    { x: points.map((p) => p.time), ys: [points.map((p) => p.viscous), points.map((p) => p.rest)] });
  const [injection, film, changeRows, viscous, rest] = budget.ys;
  c.budget.setData(budget.x, [injection, film, viscous, rest, changeRows]);
  const box = app.detail?.scene?.box_length;
  const thesisBox = Math.abs((box ?? 0) - EXPERIMENT.box) < 1e-9;
  const times = samples.map((s) => s.time);
  c.urms.setData(times, [samples.map((s) => s.u_rms), times.map(() => (thesisBox ? EXPERIMENT.urms : null))]);
  const averages = budgetAverages(samples, points);
  setText('cap-budget', budgetCaption(averages, box));
  $('chart-budget').dataset.viscousPoints = String(points.length);
  $('chart-budget').dataset.restMean = String(averages?.rest ?? '');
  setText('cap-urms', averages ? `mean ${formatNumber(averages.urms)} m/s over t ∈ [${formatNumber(averages.from)}, ${formatNumber(averages.to)}] s` : '');
}

/** The run's reference curve (GET reference): the analytic 2D decay, the 3D DNS or the laminar
 *  Kolmogorov flow, or why none; to `until` seconds if given (redraw asks again as the run goes
 *  on, so that the plotted span is sampled finely). */
export async function loadReference(id, until) {
  app.referencePending = true;
  try {
    const r = await api.reference(id, until);
    if (id !== app.selectedId) return;
    const col = columnOf(r);
    const time = col('time');
    // Complete: the curve ends before `until` (the run's end time or the DNS' last time).
    const complete = until === undefined || !(time.length && time[time.length - 1] >= until * (1 - 1e-9));
    app.reference = { id, label: r.label, source: r.source, time, energy: col('kinetic_energy'), dissipation: col('dissipation'), until: until ?? Infinity, complete };
    app.referenceRetry = { failures: 0, at: 0 };
  } catch (e) {
    if (id === app.selectedId && !isCancelled(e)) {
      // A refetch that fails keeps the curve it had; the next try waits 1, 2, 4 … 60 s.
      if (!app.reference) app.referenceWhy = errorText(e);
      const failures = app.referenceRetry.failures + 1;
      app.referenceRetry = { failures, at: Date.now() + Math.min(60_000, 1000 * 2 ** (failures - 1)) };
    }
  } finally {
    if (id === app.selectedId) app.referencePending = false;
  }
  scheduleRedraw();
}

/** Asks for the reference again when the span it was sampled over is far from the plotted one:
 *  more than four times longer, or shorter while the curve goes on. */
function refreshReferenceSpan(horizon) {
  const ref = app.reference;
  if (!ref || ref.id !== app.selectedId || app.referencePending || !Number.isFinite(horizon)) return;
  if (Date.now() < app.referenceRetry.at) return;
  if (ref.until > 4 * horizon || (ref.until < horizon && !ref.complete)) loadReference(app.selectedId, 2 * horizon);
}
