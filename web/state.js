// SPDX-License-Identifier: GPL-3.0-or-later
// The dashboard's shared state (`app`: the run list, the selected run and what the page shows of
// it) and the small helpers every view uses: element lookup, status lines, error texts, dotted
// scene paths, number and size formatting.

import { ApiError } from './api.js';

// The page's image panels (index.html: img-FIELD, cap-FIELD); the create form takes the fields
// the server renders live from its presets.
export const IMAGE_FIELDS = ['omega2', 'tau_sfs', 'view3d'];

export const $ = (id) => document.getElementById(id);

export const app = {
  runs: [],
  presets: [],
  sceneSchema: null,  // GET /api/schema/scene: the form's options, bounds and tooltips
  validateScene: null,  // ajv's validator of that schema, when the page has ajv
  compared: new Map(),  // run id → {label, time, energy, dissipation, detail, resolved} overlaid on the plots
  selectedId: null,
  autoSelect: true,    // pick a run for the user (on opening the page, until one is closed)
  runsGeneration: 0,   // run deletions by this page: older run lists are stale
  summary: null,  // run summary of the selected run (from the list, the stream or an action)
  detail: null,   // run detail (scene, changeable, counters)
  stream: null,
  samples: [],    // metrics samples of the selected run, ordered by step
  analysis: [],   // [{time, spectral, vorticity}]
  stats: [],      // [{time, max, mean}]
  spectrum: null,
  frames: [],     // saved frames grouped by step: [{time, step, files: {field: file}}]
  live: true,
  liveImage: {},  // field → {blob, header} of the newest live image not yet shown
  shownUrl: {},   // field → object URL currently in its <img>
  reference: null,        // the selected run's reference curve, sampled to `until`
  referenceWhy: null,     // why it has none
  referencePending: false,
  referenceRetry: { failures: 0, at: 0 },  // back-off of failed refetches (loadReference)
  referenceJob: null,     // the spectral reference job of the selected run's flow it follows
  referenceJobTimer: null,
  availableAfterSpectrum: false,  // ask again what the run has once its first spectrum arrives
  charts: null,
  redrawTimer: null,
  busy: false,
};

export function setText(id, text) {
  const el = $(id);
  if (el.textContent !== text) el.textContent = text;
}

export function showStatus(id, text, kind = '') {
  const el = $(id);
  el.textContent = text;
  el.dataset.kind = kind;
}

/** Whether `e` is a request this page cancelled itself (not an error to show). */
export function isCancelled(e) {
  return e instanceof ApiError && e.cancelled;
}

export function errorText(e) {
  if (e instanceof ApiError) {
    if (e.status === 401) return `${e.message} — set the server's token in the Token field.`;
    return e.status ? `${e.message} (HTTP ${e.status})` : e.message;
  }
  return String(e && e.message ? e.message : e);
}

export function getPath(object, path) {
  return path.split('.').reduce((o, k) => (o && typeof o === 'object' ? o[k] : undefined), object);
}

export function setPath(object, path, value) {
  const keys = path.split('.');
  let o = object;
  for (const k of keys.slice(0, -1)) {
    if (!o[k] || typeof o[k] !== 'object') o[k] = {};
    o = o[k];
  }
  o[keys[keys.length - 1]] = value;
}

export function fmtSeconds(s) {
  if (!Number.isFinite(s)) return '–';
  if (s < 120) return `${s.toFixed(1)} s`;
  if (s < 7200) return `${(s / 60).toFixed(1)} min`;
  return `${(s / 3600).toFixed(2)} h`;
}

/** Whether the server accepts `verb` for a run or a reference job now: its `actions`
 *  (RunSummary.actions, ReferenceJob.actions), listed by the rules that refuse the others. */
export function allows(item, verb) {
  return Array.isArray(item?.actions) && item.actions.includes(verb);
}

/** A run or reference job under way, which the page polls: one the server would stop. */
export function isActive(item) {
  return allows(item, 'stop');
}

export function finite(v) {
  return typeof v === 'number' && Number.isFinite(v) ? v : null;
}

/** fmtSeconds, with times under a second in ms (a step's cost). */
export function fmtDuration(s) {
  return s > 0 && s < 1 ? `${(s * 1e3).toPrecision(3)} ms` : fmtSeconds(s);
}

export function fmtBytes(b) {
  const units = ['B', 'KiB', 'MiB', 'GiB', 'TiB'];
  let i = 0;
  while (b >= 1024 && i < units.length - 1) { b /= 1024; i += 1; }
  return `${i ? b.toPrecision(3) : b} ${units[i]}`;
}

/** A column of a {columns, data} answer (time series, analysis, reference) by name; [] if absent. */
export function columnOf(answer) {
  const columns = Array.isArray(answer?.columns) ? answer.columns : [];
  const data = Array.isArray(answer?.data) ? answer.data : [];
  return (name) => data[columns.indexOf(name)] ?? [];
}

/** A form field's value: a number for a number input, undefined when it is empty. */
export function readInput(input) {
  const raw = input.value.trim();
  if (raw === '') return undefined;
  if (input.type === 'number') {
    const v = Number(raw);
    if (!Number.isFinite(v)) throw new Error(`'${input.dataset.path}' is not a number`);
    if (input.dataset.type === 'int' && !Number.isInteger(v))
      throw new Error(`'${input.dataset.path}' must be an integer`);
    return v;
  }
  return raw;
}
