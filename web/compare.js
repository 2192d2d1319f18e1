// SPDX-License-Identifier: GPL-3.0-or-later
// Runs compared at equal times: the time slider shared by the selected run and the runs ticked
// "compare" (each run's spectrum nearest to the chosen time, read from its spectra/index.csv and
// spectrum files through GET .../files), and the table of the runs' parameters and their errors
// against the reference run of their flow (GET .../resolved). plots.js draws what this picks.

import { api } from './api.js';
import { formatNumber } from './charts.js';
import { $, app, setText, errorText, isCancelled, getPath, isActive, finite } from './state.js';

const REFRESH_MS = 3000;  // a running run's spectra index and resolved scales, at most this often
const CACHED_FILES = 400; // spectrum files kept (a few KiB each): scrubbing back needs no request
// What GET resolved answers for a run of a flow without a reference run; it is not asked then
// (the 404 would be logged by the browser as an error).
const NO_REFERENCE = 'no reference run of this flow in the server\'s reference data or done ' +
  'reference jobs (GET /api/runs/{id}/resolved answers 404; "Compute reference" on the run ' +
  'computes one, docs/reference.md)';

// plots.js' redraw, which it hands over (it imports this module: the reverse would be a cycle).
let scheduleRedraw = () => {};
export function redrawWith(redraw) {
  scheduleRedraw = redraw;
}

/** Per run id: its spectra index {rows: [{t, file}] by time, listed, pending, at, why}. */
const indexes = new Map();
/** `${id}/${file}` → {k, energy}, or 'loading', or 'failed'. */
const files = new Map();
let sliderRun = null;       // the selected run whose spectra's times the slider holds
let position = null;        // the chosen row of its index; null: its latest spectrum, live
let ownCaptionSet = false;  // cap-spectrum names the slider's time, not the latest spectrum's
let tableShown = '';        // what the table shows, so that a redraw without news keeps it
// The selected run's detail as the table shows it: app.detail is the one of its selection, which
// a live change of η (the parameter form) leaves as it was.
const own = { id: null, detail: null, at: 0, pending: false };

/** The runs compared with the selected one (not itself), in the order they were ticked: the
 *  order of plots.js' extra series, and so of their colours. */
function comparedIds() {
  return [...app.compared.keys()].filter((id) => id !== app.selectedId);
}

/** What the comparison needs of a run ticked "compare" beside its time series: its scene
 *  (`detail`, GET /api/runs/{id}), its resolved scales and its spectra's times. */
export async function loadComparedRun(id, entry, detail) {
  entry.detail = detail;
  entry.resolvedAt = 0;
  await Promise.all([loadResolvedOf(id, entry), loadIndex(id, true)]);
}

/** A compared run's resolved scales, asked for only when its detail says it has them. */
async function loadResolvedOf(id, entry) {
  if (!entry) return;
  if (!entry.detail?.available?.resolved) {
    entry.resolvedWhy = NO_REFERENCE;
    return;
  }
  if (Date.now() < entry.resolvedAt) return;
  entry.resolvedAt = Date.now() + REFRESH_MS;
  try {
    entry.resolved = await api.resolved(id);
    entry.resolvedWhy = '';
  } catch (e) {
    if (!isCancelled(e)) entry.resolvedWhy = errorText(e);
  }
  scheduleRedraw();
}

/** Rows of a CSV file by its header; a row still being appended as it is read is left out. */
function csvRows(text) {
  const lines = String(text).split(/\r?\n/).filter((l) => l.trim() !== '');
  const head = (lines.shift() ?? '').split(',');
  return lines.map((l) => l.split(',')).filter((c) => c.length === head.length)
    .map((c) => Object.fromEntries(head.map((h, i) => [h, c[i]])));
}

function indexRows(text) {
  const rows = csvRows(text).map((r) => ({ t: Number(r.t), file: r.file }))
    .filter((r) => Number.isFinite(r.t) && /^[\w.+-]+$/.test(r.file ?? ''));
  rows.sort((a, b) => a.t - b.t);
  // A restart without a final checkpoint repeats times: the later row wins (the sort is stable).
  return rows.filter((r, i) => i + 1 === rows.length || rows[i + 1].t !== r.t);
}

/** A run's spectra/index.csv, once GET files lists it (a run without spectra has none, and
 *  asking for it would be a 404); again at most every REFRESH_MS unless `force`. */
async function loadIndex(id, force = false) {
  let ix = indexes.get(id);
  if (!ix) {
    ix = { rows: [], listed: false, pending: false, at: 0, why: 'loading its spectra' };
    indexes.set(id, ix);
  }
  if (ix.pending || (!force && Date.now() < ix.at)) return;
  ix.pending = true;
  ix.at = Date.now() + REFRESH_MS;
  const before = JSON.stringify([ix.rows.length, ix.why]);
  try {
    if (!ix.listed) {
      const list = await api.files(id);
      ix.listed = Array.isArray(list) && list.some((f) => f.path === 'spectra/index.csv');
      if (!ix.listed) {
        ix.why = 'no spectra (none written yet, or no "spectrum" among its analysis products)';
        return;
      }
    }
    ix.rows = indexRows(await api.runFileText(id, 'spectra', 'index.csv'));
    ix.why = ix.rows.length ? '' : 'no spectra yet';
  } catch (e) {
    if (!isCancelled(e)) ix.why = errorText(e);
  } finally {
    ix.pending = false;
    // Only news redraws: the redraw asks again while the index lags the latest spectrum.
    if (JSON.stringify([ix.rows.length, ix.why]) !== before) scheduleRedraw();
  }
}

/** A spectrum file's {k, energy}, or null while it loads (a redraw follows) or if it failed. */
function spectrumFile(id, file) {
  const key = `${id}/${file}`;
  const got = files.get(key);
  if (got !== undefined) return typeof got === 'object' ? got : null;
  if (files.size >= CACHED_FILES) files.delete(files.keys().next().value);
  files.set(key, 'loading');
  api.runFileText(id, 'spectra', file).then((text) => {
    const rows = csvRows(text);
    files.set(key, { k: rows.map((r) => Number(r.k)), energy: rows.map((r) => Number(r.E)) });
  }).catch((e) => {
    if (isCancelled(e)) files.delete(key);
    else files.set(key, 'failed');
  }).finally(scheduleRedraw);
  return null;
}

/** The row of `rows` nearest to time t. */
function nearestRow(rows, t) {
  let best = null;
  for (const r of rows) if (!best || Math.abs(r.t - t) < Math.abs(best.t - t)) best = r;
  return best;
}

/** Whether times a and b are within `half` (half the selected run's analysis cadence). */
function near(a, b, half) {
  return Math.abs(a - b) <= half * (1 + 1e-9) + 1e-12;
}

/** Half the selected run's analysis cadence (its analysis.every, else its spectra's spacing):
 *  a run's nearest spectrum further from the chosen time is marked as of another time. */
function halfCadence(rows) {
  const scene = app.detail?.id === app.selectedId ? app.detail?.scene : null;
  const every = getPath(scene, 'analysis.every');
  if (typeof every === 'number' && every > 0) return every / 2;
  const gaps = rows.slice(1).map((r, i) => r.t - rows[i].t).sort((a, b) => a - b);
  return gaps.length ? gaps[gaps.length >> 1] / 2 : 0;
}

/** The selected run's index again when a newer spectrum has come; the compared runs' index and
 *  resolved scales while they run. */
function refresh(ids) {
  const ix = indexes.get(app.selectedId);
  const lastOwn = ix?.rows.length ? ix.rows[ix.rows.length - 1].t : -Infinity;
  if (!ix || (finite(app.spectrum?.time) ?? -Infinity) > lastOwn + 1e-12) loadIndex(app.selectedId);
  loadOwnDetail();
  for (const id of ids) {
    if (!indexes.has(id)) continue;  // its first load is under way (loadComparedRun)
    const run = app.runs.find((r) => r.id === id);
    if (!run || !isActive(run)) continue;
    loadIndex(id);
    loadResolvedOf(id, app.compared.get(id));
  }
}

/** The selected run's detail again, at most every REFRESH_MS while the table is shown. */
async function loadOwnDetail() {
  const id = app.selectedId;
  if (own.pending || (own.id === id && Date.now() < own.at)) return;
  if (own.id !== id) Object.assign(own, { id, detail: null });
  Object.assign(own, { pending: true, at: Date.now() + REFRESH_MS });
  try {
    const detail = await api.run(id);
    if (own.id === id) {
      const changed = JSON.stringify(detail?.scene) !== JSON.stringify(own.detail?.scene);
      own.detail = detail;
      if (changed) scheduleRedraw();
    }
  } catch {
    // the table keeps the detail of the run's selection
  } finally {
    own.pending = false;
  }
}

/** A compared run at time t: its nearest spectrum, drawn; none when it has not reached t. */
function comparedAt(id, time, half) {
  const name = app.compared.get(id)?.label ?? id;
  const ix = indexes.get(id);
  const none = (short, why) => ({ id, name, label: `${name}: ${short}`, k: [], energy: [], time: null, why });
  if (time === null) return none('no time', 'the selected run has no spectrum to compare at');
  if (!ix || !ix.rows.length) return none('no spectra', ix?.why || 'loading its spectra');
  const last = ix.rows[ix.rows.length - 1];
  if (last.t < time && !near(last.t, time, half))
    return none('not reached', `not reached (its latest spectrum is of t = ${formatNumber(last.t)} s)`);
  const row = nearestRow(ix.rows, time);
  const off = !near(row.t, time, half);
  const f = spectrumFile(id, row.file);
  return {
    id, name, label: off ? `${name} (t = ${formatNumber(row.t)} s)` : name,
    k: f?.k ?? [], energy: f?.energy ?? [], time: f ? row.t : null,
    why: f ? (off ? `its nearest spectrum is of t = ${formatNumber(row.t)} s` : '') : 'loading',
  };
}

/** The slider moved: a row of the selected run's spectra, or its right end (latest, live). */
export function onCompareSlide() {
  const rows = indexes.get(app.selectedId)?.rows ?? [];
  const v = Number($('compare-slider').value);
  position = v >= rows.length ? null : v;
  scheduleRedraw();
}

/**
 * What the spectrum plot shows: {own, compared, referenceShown}. `own` is the selected run's
 * spectrum at the slider's time (its latest, live, at the right end), `compared` one entry per
 * compared run ({label, k, energy, time}; k empty when nothing is drawn for it), and
 * `referenceShown` whether the reference E(k) the page has (the latest only) is of that time.
 * Also shows or hides the slider and the table, and fills them.
 */
export function spectrumView() {
  const ids = comparedIds();
  const shown = ids.length > 0 && app.selectedId !== null;
  if (app.selectedId !== sliderRun) {
    sliderRun = app.selectedId;
    position = null;
  }
  $('compare-time').hidden = !shown;
  $('cap-compare').hidden = !shown;
  $('compare-panel').hidden = !shown;
  const chart = $('chart-spectrum');
  const latest = app.spectrum;
  if (!shown) {
    position = null;
    restoreOwnCaption(latest);
    Object.assign(chart.dataset, { chosenTime: '', ownTime: '', compareTimes: '' });
    return { own: latest, compared: [], referenceShown: true };
  }
  refresh(ids);
  const rows = indexes.get(app.selectedId)?.rows ?? [];
  if (position !== null && position >= rows.length) position = null;  // a shorter index
  const slider = /** @type {HTMLInputElement} */ ($('compare-slider'));
  slider.max = String(rows.length);
  slider.value = String(position ?? rows.length);
  slider.disabled = rows.length === 0;
  const time = position === null
    ? finite(latest?.time) ?? (rows.length ? rows[rows.length - 1].t : null)
    : rows[position].t;
  let shownOwn = latest;
  if (position !== null) {
    const f = spectrumFile(app.selectedId, rows[position].file);
    shownOwn = f ? { ...f, time } : null;
    setText('cap-spectrum', `t = ${formatNumber(time)} s (compare slider; latest ${formatNumber(latest?.time)} s)`);
    ownCaptionSet = true;
  } else {
    restoreOwnCaption(latest);
  }
  const half = halfCadence(rows);
  const compared = ids.map((id) => comparedAt(id, time, half));
  const ref = app.resolved?.reference_spectrum;
  const referenceShown = !ref || time === null || near(ref.t, time, half);
  setText('compare-label', time === null ? 'no spectrum yet'
    : `${position === null ? 'latest, ' : ''}t = ${formatNumber(time)} s`);
  const notes = compared.filter((c) => c.why && c.why !== 'loading').map((c) => `${c.name}: ${c.why}`);
  if (!referenceShown) {
    notes.push(`reference E(k) not drawn: the server gives it at t = ${formatNumber(ref.t)} s ` +
      'only (GET /api/runs/{id}/resolved, its latest spectrum)');
  }
  setText('cap-compare', time === null ? 'The selected run has no spectrum yet.'
    : `Every run's spectrum nearest to t = ${formatNumber(time)} s` +
      `${notes.length ? `; ${notes.join('; ')}` : ''}.`);
  Object.assign(chart.dataset, {
    chosenTime: time === null ? '' : String(time),
    ownTime: shownOwn && finite(shownOwn.time) !== null ? String(shownOwn.time) : '',
    compareTimes: compared.map((c) => (c.time === null ? 'none' : String(c.time))).join(','),
  });
  renderTable(ids, time, half);
  return { own: shownOwn, compared, referenceShown };
}

/** cap-spectrum as messages.js words it for the latest spectrum, once the slider leaves. */
function restoreOwnCaption(latest) {
  if (!ownCaptionSet) return;
  ownCaptionSet = false;
  setText('cap-spectrum', latest ? `t = ${formatNumber(latest.time)} s, step ${latest.step ?? '–'}` +
    `${finite(latest.kernel_wavenumber) ? `, k_kern = ${formatNumber(latest.kernel_wavenumber)} 1/m` : ''}`
    : 'no spectrum yet');
}

const COLUMNS = [
  ['case', 'Case'], ['n', 'N'], ['kernel', 'Kernel'], ['dk', 'D_K/Δl'], ['scheme', 'Scheme'],
  ['model', 'Sub-filter model'], ['eta', 'η [Pa s]'], ['time', 't reached [s]'],
  ['misfit', 'E_res misfit (L2)'], ['max_error', 'max |E_res/E_res,ref − 1|'], ['ratio', 'E_res/E_res,ref'],
];

/** A cell: its text, a number for the test (data-value), a title saying why it is empty. */
const cell = (text, value = null, title = '', kind = 'number') => ({ text, value, title, kind });
const numberCell = (v, why) => (finite(v) !== null ? cell(formatNumber(v), v) : cell('–', null, why));

/** Whether a resolved sample's reference holds energy at k ≤ k_SPH (as references.js says). */
const hasResolvedReference = (s) => s.reference_resolved_energy > 1e-12 * s.reference_energy;

/** The errors against the reference: the L2 misfit, the largest relative error and its time
 *  (the server gives none: the sample of the largest error, as the server picks them), and
 *  E_res/E_res,ref at the sample nearest to the slider's time. */
function errorCells(resolved, why, time, half) {
  if (!resolved) {
    const none = cell('–', null, why || 'loading');
    return { misfit: none, max_error: none, ratio: none };
  }
  const samples = Array.isArray(resolved.samples) ? resolved.samples : [];
  const kSph = samples.length ? ` k_SPH = ${formatNumber(samples[samples.length - 1].k_sph)} 1/m` : '';
  const empty = `no sample where the reference has energy at k ≤${kSph} (a kernel this wide ` +
    `resolves none of the flow's scales), against ${resolved.reference}`;
  const max = finite(resolved.resolved_energy_max_relative_error);
  const worst = samples.filter(hasResolvedReference).find((s) =>
    max !== null && Math.abs(Math.abs(s.resolved_energy / s.reference_resolved_energy - 1) - max) <= 1e-9 * max);
  const maxCell = numberCell(max, empty);
  if (worst) maxCell.text += ` at t = ${formatNumber(worst.t)}`;
  let ratio;
  const sample = time === null ? null : nearestRow(samples, time);
  if (!sample || !near(sample.t, time, half)) {
    ratio = cell('–', null, `no resolved-scales sample within ${formatNumber(half)} s of the slider's t`);
  } else if (!hasResolvedReference(sample)) {
    ratio = cell('–', null, empty);
  } else {
    ratio = numberCell(sample.resolved_energy / sample.reference_resolved_energy, '');
    ratio.title = `at t = ${formatNumber(sample.t)} s, against ${resolved.reference}`;
  }
  const misfit = numberCell(resolved.resolved_energy_l2_misfit, empty);
  if (misfit.value !== null) misfit.title = `against ${resolved.reference}`;
  return { misfit, max_error: maxCell, ratio };
}

/** One run's row: its name, its scene's parameters, its time and its errors. */
function rowOf(id, name, detail, summary, resolved, why, time, half) {
  const scene = detail?.scene ?? {};
  const dimension = detail?.dimension ?? summary?.dimension;
  const n = scene.particles_per_side ?? detail?.particles_per_side ?? summary?.particles_per_side;
  const power = { 2: '²', 3: '³' }[dimension] ?? '';
  const text = (v) => cell(v === undefined || v === null || v === '' ? '–' : String(v), null, '', 'text');
  return {
    id, name,
    cells: {
      case: text(scene.case ?? summary?.case),
      n: Number.isFinite(n) ? cell(`${n}${power}`, n) : cell('–', null, 'loading the run\'s scene'),
      kernel: text(getPath(scene, 'kernel.type')),
      dk: numberCell(getPath(scene, 'kernel.diameter_over_spacing'), 'loading the run\'s scene'),
      scheme: text(getPath(scene, 'scheme.type')),
      model: text(getPath(scene, 'subfilter.model')),
      eta: numberCell(getPath(scene, 'fluid.dynamic_viscosity'), 'loading the run\'s scene'),
      time: numberCell(summary?.time, ''),
      ...errorCells(resolved, why, time, half),
    },
  };
}

function renderTable(ids, time, half) {
  const selected = app.selectedId;
  const detail = own.id === selected && own.detail ? own.detail : app.detail;
  const first = rowOf(selected, app.summary?.name || selected,
    detail?.id === selected ? detail : null, app.summary,
    app.resolved, app.resolvedAvailable ? 'loading' : NO_REFERENCE, time, half);
  const rows = [first, ...ids.map((id) => {
    const entry = app.compared.get(id);
    return rowOf(id, entry?.label ?? id, entry?.detail, app.runs.find((r) => r.id === id),
      entry?.resolved, entry?.resolvedWhy || 'loading', time, half);
  })];
  const at = time === null ? '' : ` at t = ${formatNumber(time)} s`;
  const signature = JSON.stringify([at, rows]);
  if (signature === tableShown) return;
  tableShown = signature;
  const table = $('compare-table');
  const head = document.createElement('tr');
  for (const [key, name] of [['run', 'Run'], ...COLUMNS]) {
    const th = document.createElement('th');
    th.scope = 'col';
    th.textContent = key === 'ratio' ? `${name}${at}` : name;
    head.append(th);
  }
  const body = rows.map((r) => {
    const tr = document.createElement('tr');
    tr.dataset.id = r.id;
    const th = document.createElement('th');
    th.scope = 'row';
    th.textContent = r.name;
    tr.append(th);
    for (const [key] of COLUMNS) {
      const c = r.cells[key];
      const td = document.createElement('td');
      td.dataset.field = key;
      if (c.value !== null) td.dataset.value = String(c.value);
      td.dataset.kind = c.kind;
      if (c.title) td.title = c.title;
      td.textContent = c.text;
      tr.append(td);
    }
    return tr;
  });
  const thead = document.createElement('thead');
  thead.append(head);
  const tbody = document.createElement('tbody');
  tbody.append(...body);
  table.replaceChildren(thead, tbody);
  table.dataset.rows = String(body.length);
  setText('cap-compare-table', `the selected run first; errors against the reference run of each ` +
    `run's flow (GET /api/runs/{id}/resolved)${at ? `, E_res/E_res,ref${at}` : ''}`);
}
