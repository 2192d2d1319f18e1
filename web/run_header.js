// SPDX-License-Identifier: GPL-3.0-or-later
// The selected run's header: its name, state, progress, timings and the control buttons the
// server accepts now; its summary merged from the list, the stream and the answers to actions.

import { formatNumber } from './charts.js';
import { IMAGE_FIELDS, $, app, setText, fmtSeconds, allows, finite } from './state.js';
import { fillParamForm } from './live_parameters.js';

// What a running run is doing before its first step (RunSummary.phase); nothing once it steps.
const PHASE_TEXT = {
  packing: 'packing the initial lattice…',
  restoring: 'reading the checkpoint…',
  'setting up': 'setting up…',
};

export function applyDetail(detail) {
  if (!detail) return;
  app.detail = detail;
  mergeSummary(detail);
  fillParamForm(detail.scene ?? {});
  const changeable = Array.isArray(detail.changeable) ? detail.changeable : [];
  setText('param-changeable', changeable.length ? `Changeable while the run exists: ${changeable.join(', ')}.` : '');
}

export function mergeSummary(s) {
  if (!s || s.id !== app.selectedId) return;
  const old = app.summary ?? {};
  app.summary = { ...old, ...s };
  // Metrics may be newer than a polled summary: keep the later time and step.
  if ((old.step ?? -1) > (s.step ?? -1)) {
    app.summary.step = old.step;
    app.summary.time = old.time;
    app.summary.progress = old.progress;
  }
  renderHeader();
}

export function renderHeader() {
  const s = app.summary;
  if (!s) return;
  setText('run-title', s.name || s.id);
  const badge = $('run-state');
  badge.textContent = s.state ?? '–';
  badge.dataset.state = s.state ?? '';
  // A failure is an error with its diagnosis (the launcher's report, the blow-up's location,
  // the last valid checkpoint), not a remark in parentheses.
  const failed = s.state === 'failed';
  setText('run-reason', s.reason && !failed ? `(${s.reason})` : '');
  // Before its first step a run may spend minutes packing its lattice: say so.
  setText('run-phase', PHASE_TEXT[s.phase] ?? '');
  for (const f of IMAGE_FIELDS)
    if (!$(`img-${f}`).getAttribute('src')) setText(`cap-${f}`, PHASE_TEXT[s.phase] ?? 'no image yet');
  $('run-failure').hidden = !failed;
  setText('run-failure', failed ? `Failed: ${s.reason || 'no reason given'}` : '');
  const progress = finite(s.progress) ?? (s.end_time > 0 ? (s.time ?? 0) / s.end_time : 0);
  $('run-progress').value = Math.min(1, Math.max(0, progress));
  setText('run-time', formatNumber(s.time));
  setText('run-end', formatNumber(s.end_time));
  setText('run-step', s.step === undefined ? '–' : String(s.step));
  setText('run-rate', formatNumber(s.steps_per_second));
  setText('run-wall', fmtSeconds(s.wall_seconds));
  setText('run-eta', s.state === 'running' ? fmtSeconds(estimateRemaining(s)) : '–');
  setText('run-case', `${s.case ?? '–'}${s.dimension ? ` ${s.dimension}D` : ''}${s.particles_per_side ? `, N = ${s.particles_per_side}${s.dimension === 2 ? '²' : '³'}` : ''}${s.ranks > 1 ? `, ${s.ranks} MPI ranks` : ''}`);
  $('btn-clone').disabled = !app.detail;
  // The buttons the server would accept now (RunSummary.actions).
  for (const b of document.querySelectorAll('.controls button[data-action]'))
    b.disabled = app.busy || !allows(s, b.dataset.action);
}

/** Wall seconds to the end time at the rate of the last minute of stepping (simulated time per
 *  wall second between summaries of the selected run); null until two summaries differ. */
function estimateRemaining(s) {
  const t = finite(s.time);
  const w = finite(s.wall_seconds);
  if (t === null || w === null) return null;
  const history = app.progressHistory ?? (app.progressHistory = []);
  if (!history.length || w > history[history.length - 1].w) history.push({ t, w });
  while (history.length > 2 && w - history[0].w > 60) history.shift();
  const first = history[0];
  if (!(w > first.w) || !(t > first.t)) return null;
  const rate = (t - first.t) / (w - first.w);
  return Math.max(0, (s.end_time - t) / rate);
}
