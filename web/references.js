// SPDX-License-Identifier: GPL-3.0-or-later
// The resolved scales against the reference run of the selected run's flow, and the spectral
// reference jobs that compute one (POST /api/references, docs/reference.md).

import { api } from './api.js';
import { formatNumber } from './charts.js';
import { $, app, setText, showStatus, errorText, getPath, fmtBytes, allows, isActive } from './state.js';
import { scheduleRedraw } from './plots.js';

const REFERENCE_POLL_MS = 2000;  // a reference job's progress while it is queued or running

/** The resolved scales against the reference run of the flow, at most every 2 s of wall time. */
export async function loadResolved(id) {
  if (!app.resolvedAvailable || Date.now() < app.resolvedAt) return;
  app.resolvedAt = Date.now() + 2000;
  const r = await api.resolved(id).catch(() => null);
  if (!r || id !== app.selectedId) return;
  app.resolved = r;
  showResolved(r);
  scheduleRedraw();
}

/** The latest sample's resolved energy, shell ratios and particle-scale energy as a table. */
function showResolved(r) {
  const table = $('resolved-table');
  const s = r.samples[r.samples.length - 1];
  if (!s) return;
  const ratio = (v) => (v === null || v === undefined || !Number.isFinite(v) ? '–' : v.toFixed(2));
  const rows = [
    ['t', formatNumber(s.t)],
    ['E_res / E_res,ref (k ≤ k_SPH = ' + formatNumber(s.k_sph) + ')',
      // None where the reference has no resolved energy (k_SPH below the flow's scales).
      ratio(s.reference_resolved_energy > 1e-12 * s.reference_energy
        ? s.resolved_energy / s.reference_resolved_energy : null)],
    ...s.shell.map((k, i) => [`E(k)/E_ref(k), k = ${formatNumber(k)}`, ratio(s.shell_ratio[i])]),
    ['energy above k_kern, run / reference', `${formatNumber(s.energy_above_kernel)} / ${formatNumber(s.reference_energy_above_kernel)}`],
    ['E_res misfit so far (L2)', Number.isFinite(r.resolved_energy_l2_misfit)
      ? `${(100 * r.resolved_energy_l2_misfit).toFixed(1)} %` : '–'],
  ];
  table.replaceChildren(...rows.map(([name, value]) => {
    const tr = document.createElement('tr');
    const th = document.createElement('th');
    th.textContent = name;
    const td = document.createElement('td');
    td.textContent = value;
    tr.append(th, td);
    return tr;
  }));
  table.dataset.shells = String(s.shell.length);
  setText('cap-resolved', `against ${r.reference}`);
}

/** What the run detail says exists for the resolved scales: the table when a reference run of
 *  the flow exists; else, once the run has spectra, the form that computes one. */
export function applyAvailable(id, available) {
  app.resolvedAvailable = Boolean(available.resolved);
  app.availableAfterSpectrum = !available.spectrum;
  if (app.resolvedAvailable) {
    $('reference-form').hidden = true;
    app.resolvedAt = 0;
    loadResolved(id);
  } else if (available.spectrum) {
    offerReference(id);
  }
}

/** The run detail again (its first spectrum has come, or its reference job is done). */
export async function refreshAvailable(id) {
  const detail = await api.run(id).catch(() => null);
  if (detail && id === app.selectedId) applyAvailable(id, detail.available ?? {});
}

export function resetReferenceForm() {
  clearTimeout(app.referenceJobTimer);
  app.referenceJob = null;
  $('reference-form').hidden = true;
  $('reference-form').dataset.state = '';
  $('reference-compute').disabled = false;
  $('reference-progress').hidden = true;
  $('reference-toggle').hidden = true;
  showStatus('reference-status', '');
}

/** Offers "Compute reference" for the selected run, with its scene's grid (or 64), and follows
 *  a job of this run already under way (another page, a reload). */
async function offerReference(id) {
  const form = $('reference-form');
  if (!form.hidden) return;
  form.hidden = false;
  const scene = app.detail?.id === id ? app.detail.scene : null;
  $('reference-points').value = String(getPath(scene, 'reference.points_per_side') ?? 64);
  const jobs = await api.references().catch(() => []);
  if (id !== app.selectedId || app.referenceJob) return;
  const job = jobs.filter((j) => j.run === id).pop();
  if (job) followReferenceJob(id, job);
}

/** The request of the form: the selected run and the points per side, if given. */
function referenceRequest() {
  /** @type {{ run: string, points_per_side?: number }} */
  const body = { run: app.selectedId };
  const points = $('reference-points').value.trim();
  if (points !== '') body.points_per_side = Number(points);
  return body;
}

export async function onEstimateReference() {
  const button = $('reference-estimate');
  button.disabled = true;
  try {
    const e = await api.estimateReference(referenceRequest());
    const text = `${e.points_per_side}³ points (modes |m| ≤ ${e.max_wavenumber}): ` +
      `${fmtBytes(e.memory_bytes)} at the peak of the ${fmtBytes(e.memory_limit_bytes)} allowed, ` +
      `about ${formatNumber(e.steps)} steps to t = ${formatNumber(e.end_time)} s, ` +
      `checkpoints of ${fmtBytes(e.checkpoint_bytes)}`;
    if (e.admitted) showStatus('reference-status', `${text}: fits.`, 'ok');
    else showStatus('reference-status', `${text}: refused: ${e.refusal?.message ?? ''}`, 'error');
  } catch (e) {
    showStatus('reference-status', errorText(e), 'error');
  } finally {
    button.disabled = false;
  }
}

export async function onComputeReference(event) {
  event.preventDefault();
  const id = app.selectedId;
  const button = $('reference-compute');
  button.disabled = true;
  try {
    const job = await api.computeReference(referenceRequest());
    if (id === app.selectedId) followReferenceJob(id, job);
  } catch (e) {
    showStatus('reference-status', errorText(e), 'error');
  } finally {
    button.disabled = isActive(app.referenceJob);  // one job of a run at a time
  }
}

/** Stops the job (it writes a checkpoint) or resumes it, whichever the server accepts now. */
export async function onToggleReference() {
  const id = app.selectedId;
  const job = app.referenceJob;
  if (!job) return;
  const button = $('reference-toggle');
  button.disabled = true;
  try {
    const next = await api.referenceAction(job.id, allows(job, 'stop') ? 'stop' : 'resume');
    if (id === app.selectedId) followReferenceJob(id, next);
  } catch (e) {
    showStatus('reference-status', errorText(e), 'error');
  } finally {
    button.disabled = false;
  }
}

/** Shows a job of the selected run's flow, polls it while it is under way (queued or running),
 *  and shows the resolved scales once it is done. */
function followReferenceJob(id, job) {
  clearTimeout(app.referenceJobTimer);
  app.referenceJob = job;
  showReferenceJob(job);
  if (isActive(job)) {
    app.referenceJobTimer = setTimeout(async () => {
      const next = await api.referenceJob(job.id).catch((e) => {
        showStatus('reference-status', errorText(e), 'error');
        return job;  // polled again
      });
      if (id === app.selectedId && app.referenceJob?.id === job.id) followReferenceJob(id, next);
    }, REFERENCE_POLL_MS);
  } else if (job.state === 'done') {
    refreshAvailable(id);
  }
}

function showReferenceJob(job) {
  $('reference-form').dataset.state = job.state;
  $('reference-compute').disabled = isActive(job);
  const progress = $('reference-progress');
  progress.hidden = job.state !== 'running';
  progress.value = job.progress;
  const toggle = $('reference-toggle');
  // Stop or Resume, as the server accepts them now (ReferenceJob.actions).
  toggle.hidden = !allows(job, 'stop') && !allows(job, 'resume');
  toggle.textContent = allows(job, 'stop') ? 'Stop' : 'Resume';
  const at = `t = ${formatNumber(job.time)} / ${formatNumber(job.end_time)} s, step ${job.step}`;
  const texts = {
    queued: [`Reference ${job.id} waits for the job before it.`, ''],
    running: [`Reference ${job.id}: ${at}.`, ''],
    done: [`Reference ${job.id} computed (${job.points_per_side}³ points, ${job.step} steps).`, 'ok'],
    stopped: [`Reference ${job.id} stopped at ${at}; Resume continues from its checkpoint.`, ''],
    failed: [`Reference ${job.id} failed: ${job.error}`, 'error'],
  };
  const [text, kind] = texts[job.state] ?? [`Reference ${job.id}: ${job.state}`, ''];
  showStatus('reference-status', text, kind);
}
