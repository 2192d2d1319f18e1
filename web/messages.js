// SPDX-License-Identifier: GPL-3.0-or-later
// The selected run's stream messages (docs/api.md) and the history fetched beside them: metrics
// samples, spectra, sub-filter stress statistics and the analysis estimates of the dissipation.

import { ApiError, api } from './api.js';
import { formatNumber } from './charts.js';
import { app, setText, showStatus, errorText, finite, columnOf } from './state.js';
import { scheduleRedraw } from './plots.js';
import { pollSoon } from './runs.js';
import { refreshLog, refreshFiles } from './run_files.js';
import { applyDetail, mergeSummary } from './run_header.js';
import { loadResolved, refreshAvailable } from './references.js';

export function onStreamMessage(id, m) {
  if (id !== app.selectedId || !m || typeof m !== 'object') return;
  switch (m.type) {
    case 'hello':
      applyDetail(m.run);
      // Lines written between the log's fetch at selection and this stream's start (a run that
      // failed meanwhile sends no 'state' message to it) are read now.
      refreshLog();
      break;
    case 'state': {
      // The message carries the new state's actions (the server's rules); the run list asked
      // for now (pollSoon) brings the rest of the summary.
      const actions = Array.isArray(m.actions) ? m.actions : [];
      mergeSummary({ id, state: m.state, reason: m.reason ?? '', actions });
      pollSoon();
      refreshLog();
      refreshFiles();
      // Frames without a spectrum or statistics product reach the page through the history
      // only: at its end a run's last frames are read again (the budget's ν⟨ω²⟩ needs them).
      if (!['running', 'queued', 'created'].includes(m.state))
        api.analysisHistory(id).then((h) => { if (id === app.selectedId) addAnalysisHistory(h); }).catch(() => {});
      break;
    }
    case 'metrics':
      addSamples(Array.isArray(m.samples) ? m.samples : []);
      break;
    case 'spectrum':
      onSpectrum(m);
      break;
    case 'statistics':
      onStatistics(m);
      break;
    case 'changed':
      showStatus('param-status', `Changed: ${(m.changed ?? []).join(', ') || 'nothing'}.`, 'ok');
      refreshLog();
      pollSoon();  // the actions may change with it (a run at its time.end starts once it is later)
      break;
    case 'error':
      showStatus('param-status', errorText(new ApiError(m.error?.status ?? 0, m.error?.message ?? 'error', m.error?.field)), 'error');
      break;
    default:
      break;  // newer message types: ignored
  }
}

// The forced flow's columns (sim/case_diagnostics.hpp), kept when a sample has them.
const CASE_COLUMNS = ['energy_injection', 'film_dissipation', 'u_rms'];

function toSample(s) {
  const sample = {
    time: finite(s.time), step: s.step, kinetic_energy: finite(s.kinetic_energy),
    dissipation: finite(s.dissipation),
  };
  for (const c of CASE_COLUMNS) if (c in s) sample[c] = finite(s[c]);
  return sample;
}

function addSamples(list) {
  const samples = app.samples;
  for (const raw of list) {
    const s = toSample(raw);
    if (s.time === null || typeof s.step !== 'number') continue;
    const last = samples[samples.length - 1];
    if (!last || s.step > last.step) {
      samples.push(s);
    } else {
      // Out of order (the REST backfill and the stream overlap): insert unless present.
      let lo = 0;
      let hi = samples.length;
      while (lo < hi) {
        const mid = (lo + hi) >> 1;
        if (samples[mid].step < s.step) lo = mid + 1;
        else hi = mid;
      }
      if (samples[lo]?.step !== s.step) samples.splice(lo, 0, s);
    }
  }
  const last = samples[samples.length - 1];
  if (last && app.summary && last.step >= (app.summary.step ?? -1)) {
    const end = app.summary.end_time;
    // Metrics come from steps: the set-up's phase ("packing …") is over.
    mergeSummary({
      id: app.selectedId, time: last.time, step: last.step, phase: 'stepping',
      progress: end > 0 ? Math.min(1, last.time / end) : app.summary.progress,
    });
  }
  scheduleRedraw();
}

export function addTimeseries(series) {
  const col = columnOf(series);
  const time = col('time');
  const step = col('step');
  const energy = col('kinetic_energy');
  const dissipation = col('dissipation');
  const extra = CASE_COLUMNS.filter((c) => (series.columns ?? []).includes(c)).map((c) => [c, col(c)]);
  const rows = [];
  for (let i = 0; i < time.length; i++) {
    const row = { time: time[i], step: step[i], kinetic_energy: energy[i], dissipation: dissipation[i] };
    for (const [c, values] of extra) row[c] = values[i];
    rows.push(row);
  }
  addSamples(rows);
}

/** The analysis frames written before the page connected (GET analysis): the dissipation
 *  estimates and the sub-filter stress over the whole run, also after a reload or a restart. */
export function addAnalysisHistory(history) {
  const col = columnOf(history);
  const time = col('time');
  const spectral = col('dissipation_spectral');
  const vorticity = col('dissipation_vorticity');
  const max = col('tau_sfs_max');
  const mean = col('tau_sfs_mean');
  for (let i = 0; i < time.length; i++) {
    const t = finite(time[i]);
    if (t === null) continue;
    addAnalysisPoint({ time: t, spectral: finite(spectral[i]), vorticity: finite(vorticity[i]) });
    if (finite(max[i]) !== null && !app.stats.some((s) => s.time === t))
      app.stats.push({ time: t, max: finite(max[i]), mean: finite(mean[i]) });
  }
  app.stats.sort((a, b) => a.time - b.time);
  scheduleRedraw();
}

export function onSpectrum(m) {
  app.spectrum = m;
  if (app.selectedId && app.availableAfterSpectrum) {
    app.availableAfterSpectrum = false;
    refreshAvailable(app.selectedId);
  }
  if (app.selectedId) loadResolved(app.selectedId);
  const vorticity = finite(m.dissipation_vorticity) ?? finite(m.vorticity?.dissipation);
  addAnalysisPoint({ time: finite(m.time), spectral: finite(m.dissipation), vorticity });
  setText('cap-spectrum', `t = ${formatNumber(m.time)} s, step ${m.step ?? '–'}` +
    `${finite(m.kernel_wavenumber) ? `, k_kern = ${formatNumber(m.kernel_wavenumber)} 1/m` : ''}`);
  scheduleRedraw();
}

function addAnalysisPoint(p) {
  if (p.time === null || (p.spectral === null && p.vorticity === null)) return;
  const i = app.analysis.findIndex((a) => a.time === p.time);
  if (i >= 0) {
    for (const [k, v] of Object.entries(p)) if (v !== null) app.analysis[i][k] = v;
  }
  else app.analysis.push(p);
  app.analysis.sort((a, b) => a.time - b.time);
}

export function onStatistics(m) {
  const time = finite(m.time);
  if (time !== null && !app.stats.some((s) => s.time === time)) {
    app.stats.push({ time, max: finite(m.max_norm), mean: finite(m.mean_norm) });
    app.stats.sort((a, b) => a.time - b.time);
  }
  const vorticity = finite(m.dissipation_vorticity);
  if (vorticity !== null) addAnalysisPoint({ time, vorticity });
  app.latestStatistics = m;
  setText('cap-stats', `t = ${formatNumber(m.time)} s: max ${formatNumber(m.max_norm)} Pa, mean ${formatNumber(m.mean_norm)} Pa`);
  scheduleRedraw();
}
