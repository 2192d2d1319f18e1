// SPDX-License-Identifier: GPL-3.0-or-later
// sphles dashboard: run list, run creation, and for the selected run live images, plots,
// parameter changes and run control. Talks only to the sphles server that served this page
// (REST + one WebSocket per selected run, docs/api.md); no build step at run time.

import { api, ApiError, cancelRunRequests, getToken, setToken } from './api.js';
import { RunStream } from './stream.js';
import {
  plottingAvailable, formatNumber, energyChart, dissipationChart, spectrumChart,
  statisticsChart, spectrumData, drawJointHistogram, drawAlignmentHistogram,
} from './charts.js';

const POLL_MS = 2000;
const REFERENCE_POLL_MS = 2000;  // a reference job's progress while it is queued or running
const REFERENCE_ACTIVE = new Set(['queued', 'running']);
const LOG_POLL_MS = 3000;  // the selected run's log while it is active
const LOG_LINES = 500;     // of run.log shown
const REDRAW_MS = 250;
const IMAGE_FIELDS = ['omega2', 'tau_sfs'];
const ACTIVE = new Set(['created', 'queued', 'running', 'paused']);
// Which buttons each state allows (control/run.hpp: created/stopped → start, running → pause,
// paused → resume, anything not terminal → stop; a run that is not active can be deleted).
const ALLOWED = {
  created: ['start', 'stop', 'delete'],
  queued: ['stop'],
  running: ['pause', 'stop'],
  paused: ['resume', 'stop'],
  stopped: ['start', 'delete'],
  finished: ['delete'],
  failed: ['delete'],
};
// What a running run is doing before its first step (RunSummary.phase); nothing once it steps.
const PHASE_TEXT = {
  packing: 'packing the initial lattice…',
  restoring: 'reading the checkpoint…',
  'setting up': 'setting up…',
};
const LIVE_PRODUCTS = ['energy', 'spectrum', 'vorticity', 'slices', 'sfs_stats'];
/** Labels of the analysis products the form offers (the names come from the scene schema). */
const PRODUCT_LABELS = {
  energy: 'energy, dissipation',
  spectrum: 'E(k) spectra',
  vorticity: '⟨ω²⟩',
  slices: 'slice images',
  sfs_stats: 'τ_SFS statistics',
  particles: 'particle snapshots (HDF5 + XDMF)',
  fields: 'grid fields (.vti)',
};

const $ = (id) => document.getElementById(id);

const app = {
  runs: [],
  presets: [],
  sceneSchema: null,  // GET /api/schema/scene: the form's options, bounds and tooltips
  validateScene: null,  // ajv's validator of that schema, when the page has ajv
  compared: new Map(),  // run id → {label, time, energy, dissipation, spectrum} overlaid on the plots
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

// ---------------------------------------------------------------- small helpers

function setText(id, text) {
  const el = $(id);
  if (el.textContent !== text) el.textContent = text;
}

function showStatus(id, text, kind = '') {
  const el = $(id);
  el.textContent = text;
  el.dataset.kind = kind;
}

/** Whether `e` is a request this page cancelled itself (not an error to show). */
function isCancelled(e) {
  return e instanceof ApiError && e.cancelled;
}

function errorText(e) {
  if (e instanceof ApiError) {
    if (e.status === 401) return `${e.message} — set the server's token in the Token field.`;
    return e.status ? `${e.message} (HTTP ${e.status})` : e.message;
  }
  return String(e && e.message ? e.message : e);
}

function getPath(object, path) {
  return path.split('.').reduce((o, k) => (o && typeof o === 'object' ? o[k] : undefined), object);
}

function setPath(object, path, value) {
  const keys = path.split('.');
  let o = object;
  for (const k of keys.slice(0, -1)) {
    if (!o[k] || typeof o[k] !== 'object') o[k] = {};
    o = o[k];
  }
  o[keys[keys.length - 1]] = value;
}

function fmtSeconds(s) {
  if (!Number.isFinite(s)) return '–';
  if (s < 120) return `${s.toFixed(1)} s`;
  if (s < 7200) return `${(s / 60).toFixed(1)} min`;
  return `${(s / 3600).toFixed(2)} h`;
}

function finite(v) {
  return typeof v === 'number' && Number.isFinite(v) ? v : null;
}

// ---------------------------------------------------------------- run list (polled)

async function pollRuns() {
  try {
    const generation = app.runsGeneration;
    const runs = await api.runs();
    // A list asked for before this page deleted a run may still hold it: wait for the next.
    if (generation !== app.runsGeneration) return;
    app.runs = Array.isArray(runs) ? runs : [];
    const el = $('api-state');
    el.dataset.state = 'open';
    el.textContent = `server: ok · ${app.runs.length} run${app.runs.length === 1 ? '' : 's'}`;
    renderRunList();
    if (app.selectedId) {
      const s = app.runs.find((r) => r.id === app.selectedId);
      if (s) mergeSummary(s);
      else deselectRun();  // deleted elsewhere
    } else if (app.runs.length && app.autoSelect) {
      // On opening the page only: the run the address names, else the newest active one.
      const fromHash = new URLSearchParams(location.hash.slice(1)).get('run');
      const pick = app.runs.find((r) => r.id === fromHash) ??
        [...app.runs].reverse().find((r) => ACTIVE.has(r.state)) ?? app.runs[app.runs.length - 1];
      selectRun(pick.id);
    }
  } catch (e) {
    const el = $('api-state');
    el.dataset.state = 'reconnecting';
    el.textContent = `server: ${e.status === 0 ? 'unreachable' : errorText(e)} · retrying`;
  } finally {
    setTimeout(pollRuns, POLL_MS);
  }
}

/** Calls `select(id)` when a run's item is clicked and `compare(id, on)` when its compare box is
 *  ticked or cleared: one listener each on the list, whose items renderRunList keeps or adds. */
function listenToRunList(select, compare) {
  const list = $('run-list');
  list.addEventListener('click', (e) => {
    const button = /** @type {Element} */ (e.target).closest('button.run-item');
    if (button) select(button.closest('li').dataset.id);
  });
  list.addEventListener('change', (e) => {
    const box = /** @type {HTMLInputElement} */ (e.target);
    if (box.matches('.compare input')) compare(box.closest('li').dataset.id, box.checked);
  });
}

function renderRunList() {
  const list = $('run-list');
  $('run-list-empty').hidden = app.runs.length > 0;
  const items = [];
  for (const run of [...app.runs].reverse()) {
    let li = list.querySelector(`li[data-id="${CSS.escape(run.id)}"]`);
    if (!li) {
      li = document.createElement('li');
      li.dataset.id = run.id;
      li.innerHTML = `<button type="button" class="run-item">
          <span class="run-name"></span><span class="state"></span>
          <progress max="1" value="0"></progress>
          <span class="run-meta muted small"></span></button>
        <label class="compare small muted" title="overlay this run's eᵥ(t), ε(t) and E(k) on the selected run's plots"><input type="checkbox"> compare</label>`;
    }
    li.querySelector('.compare input').checked = app.compared.has(run.id);
    const button = li.querySelector('button');
    button.setAttribute('aria-current', run.id === app.selectedId ? 'true' : 'false');
    li.querySelector('.run-name').textContent = run.name || run.id;
    const badge = li.querySelector('.state');
    badge.textContent = run.state;
    badge.dataset.state = run.state;
    const progress = li.querySelector('progress');
    progress.value = Math.min(1, Math.max(0, run.progress ?? 0));
    const pct = `${Math.round(100 * (run.progress ?? 0))} %`;
    progress.setAttribute('aria-label', `${run.name || run.id}: ${pct}`);
    li.querySelector('.run-meta').textContent =
      `${run.id} · ${run.case ?? ''} ${run.dimension ? `${run.dimension}D` : ''} · ` +
      `t = ${formatNumber(run.time)} / ${formatNumber(run.end_time)} s · ${pct}`;
    items.push(li);
  }
  list.replaceChildren(...items);
}

// ---------------------------------------------------------------- run creation

async function loadPresets() {
  let presets = [];
  try {
    presets = await api.presets();
  } catch (e) {
    showStatus('create-status', `Could not load presets: ${errorText(e)}`, 'error');
  }
  app.presets = Array.isArray(presets) ? presets.slice() : [];
  renderPresetOptions();
  // The first choice is a flow sphles has references for from its first plot (the DNS' e_v,
  // the spectral reference's E(k) and resolved scales): the 3D vortex at Re = 1600; else the 2D
  // vortex (its analytic decay).
  const first = ['tgv3d-re1600', 'tgv2d'].map((name) => app.presets.findIndex((p) => p.name === name))
    .find((i) => i >= 0) ?? 0;
  $('create-preset').value = String(Math.max(0, first));
  fillCreateForm();
}

function renderPresetOptions() {
  const select = $('create-preset');
  select.replaceChildren(...app.presets.map((p, i) => {
    const o = document.createElement('option');
    o.value = String(i);
    const n = p.particles_per_side ?? getPath(p.defaults, 'particles_per_side');
    const dim = p.dimension ?? (p.case && p.case.includes('2d') ? 2 : 3);
    o.textContent = `${p.builtinScene ? 'scene: ' : ''}${p.name}${n ? ` (${n}${dim === 2 ? '²' : '³'})` : ''}`;
    return o;
  }));
}

/** Clone…: the selected run's whole scene becomes the form's first choice (one clone at a time);
 *  the fields show its values, what is changed goes as a patch over it, Create makes a new run. */
async function cloneSelectedRun() {
  if (!app.selectedId) return;
  let detail;
  try {
    detail = await api.run(app.selectedId);  // the scene as it is now, live changes included
  } catch (e) {
    showStatus('create-status', `Could not read the run to clone: ${errorText(e)}`, 'error');
    return;
  }
  if (!detail.scene) return;
  const scene = JSON.parse(JSON.stringify(detail.scene));
  app.presets = app.presets.filter((p) => !p.clone);
  app.presets.unshift({
    name: `clone of ${detail.id}`,
    case: scene.case,
    dimension: detail.dimension,
    particles_per_side: scene.particles_per_side,
    description: `The scene of run ${detail.id} as it is now (every key, its analysis and render ` +
      'sections included); change what you want, then Create.',
    scene,
    builtinScene: true,
    clone: true,
  });
  renderPresetOptions();
  $('create-preset').value = '0';
  fillCreateForm();
  $('create-live').checked = false;  // the clone keeps its own analysis and render sections
  applyLiveChoice();
  $('create-name').value = `${scene.name ?? detail.id}-clone`;
  $('create-ranks').value = String(detail.ranks ?? 1);
  showStatus('create-status', `Form filled with run ${detail.id}'s scene: edit, then Create.`, 'ok');
  $('create-preset').focus();
}

function selectedPreset() {
  return app.presets[Number($('create-preset').value)] ?? null;
}

function fillCreateForm() {
  const preset = selectedPreset();
  if (!preset) return;
  $('create-description').textContent = preset.description ?? '';
  // The preset's scene document holds only what differs from the case defaults; the entry's
  // own fields and the built-in defaults fill in the rest. Empty inputs keep the preset's value.
  const flat = {
    particles_per_side: preset.particles_per_side,
    'kernel.type': preset.kernel,
    'subfilter.model': preset.subfilter_model,
    'time.end': preset.end_time,
  };
  const products = defaultProducts(preset);
  for (const box of productBoxes()) box.checked = products.has(box.value);
  for (const input of $('create-form').querySelectorAll('[data-path]')) {
    const path = input.dataset.path;
    let value = getPath(preset.scene, path);
    if (value === undefined) value = flat[path];
    if (value === undefined) value = getPath(preset.defaults, path);
    const text = value === undefined || value === null ? '' : String(value);
    input.value = text;
    input.dataset.initial = text;
  }
}

function readInput(input) {
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

function buildCreateRequest() {
  const preset = selectedPreset();
  if (!preset) throw new Error('no preset selected');
  // Only the parameters the user changed go into the patch; the preset keeps the rest.
  const patch = {};
  for (const input of $('create-form').querySelectorAll('[data-path]')) {
    if (input.value === input.dataset.initial) continue;
    const v = readInput(input);
    if (v !== undefined) setPath(patch, input.dataset.path, v);
  }
  if ($('create-live').checked) {
    const every = Number($('create-every').value);
    if (!(every > 0)) throw new Error("'analysis.every' must be > 0 for live analysis");
    const products = productBoxes().filter((b) => b.checked).map((b) => b.value);
    if (!products.length) throw new Error("'analysis.products': choose at least one product for live analysis");
    patch.analysis = { every, products };
    if (products.includes('slices')) {
      // The live images are the slices rendered: ω² and |τ_SFS| beside what the preset slices.
      const sliceFields = new Set([...(getPath(preset.scene, 'analysis.slice.fields') ?? []), ...IMAGE_FIELDS]);
      patch.analysis.slice = { fields: [...sliceFields] };
      patch.render = { fields: IMAGE_FIELDS, combined: false };
    }
  }
  const invalid = sceneSchemaError(mergePatch(preset.scene ?? {}, patch));
  if (invalid) throw new Error(`scene: ${invalid}`);
  const body = preset.builtinScene ? { scene: { ...preset.scene } } : { preset: preset.name };
  if (Object.keys(patch).length) body.patch = patch;
  const name = $('create-name').value.trim();
  if (name) body.name = name;
  const ranks = Number($('create-ranks').value);
  if (!Number.isInteger(ranks) || ranks < 1) throw new Error("'ranks' must be an integer >= 1");
  if (ranks > 1) body.ranks = ranks;
  body.start = $('create-start').checked;
  return body;
}

/** The form's create request, or null after showing why the form cannot make one. */
function formRequest() {
  try {
    return buildCreateRequest();
  } catch (e) {
    showStatus('create-status', e.message, 'error');
    return null;
  }
}

async function onCreate(event) {
  event.preventDefault();
  const body = formRequest();
  if (!body) return;
  const button = $('create-submit');
  button.disabled = true;
  showStatus('create-status', 'Creating…');
  try {
    const run = await api.create(body);
    showStatus('create-status', `Created ${run.name || run.id} (${run.state}).`, 'ok');
    app.runs = app.runs.filter((r) => r.id !== run.id).concat([run]);
    renderRunList();
    selectRun(run.id);
  } catch (e) {
    showStatus('create-status', errorText(e), 'error');
  } finally {
    button.disabled = false;
  }
}

/** fmtSeconds, with times under a second in ms (a step's cost). */
function fmtDuration(s) {
  return s > 0 && s < 1 ? `${(s * 1e3).toPrecision(3)} ms` : fmtSeconds(s);
}

function fmtBytes(b) {
  const units = ['B', 'KiB', 'MiB', 'GiB', 'TiB'];
  let i = 0;
  while (b >= 1024 && i < units.length - 1) { b /= 1024; i += 1; }
  return `${i ? b.toPrecision(3) : b} ${units[i]}`;
}

/** The form's run, estimated by the server before it is created (POST /api/estimate). */
async function onEstimate() {
  const body = formRequest();
  if (!body) return;
  const button = $('create-estimate');
  const result = $('create-estimate-result');
  button.disabled = true;
  result.hidden = true;
  showStatus('create-status', 'Estimating (a short calibration on the server)…');
  try {
    const e = await api.estimate(body);
    const rows = [
      ['particles', `${Math.round(e.particles).toLocaleString('en-US')} (${Math.round(e.neighbours_per_particle)} neighbours each)`],
      ['memory', `${fmtBytes(e.memory_bytes)} at the peak (server allows ${fmtBytes(e.memory_limit_bytes)})`],
      ['checkpoints', `${fmtBytes(e.checkpoint_disk_bytes)} on disk`],
      ['steps', `${formatNumber(e.steps)} at the initial step`],
    ];
    // A run on MPI ranks: what each rank holds (its sub-box's particles and halo copies).
    const r = e.per_rank;
    if (r) {
      rows.splice(2, 0, ['per rank', `${fmtBytes(r.memory_bytes)} on each of ${r.ranks} ranks (${r.grid.join(' × ')}): ` +
        `${Math.round(r.owned).toLocaleString('en-US')} particles and ${r.halo_per_owned.toPrecision(2)} halo copies each` +
        (r.refusal ? `; refused: ${r.refusal}` : '')]);
      // What admission charges this machine: the server's share (analysis, rendering, gathered
      // snapshots) and the ranks when they run here; with --rank-memory only the share.
      if (e.memory_here_bytes !== undefined) {
        const where = e.rank_memory_limit_bytes === null
          ? `the ${r.ranks} ranks run here, beside the server's ${fmtBytes(r.service_bytes)}`
          : `the server's ${fmtBytes(r.service_bytes)}; the ranks run elsewhere, up to ${fmtBytes(e.rank_memory_limit_bytes)} each`;
        rows.splice(3, 0, ['this machine', `${fmtBytes(e.memory_here_bytes)} of the ${fmtBytes(e.memory_limit_bytes)} allowed (${where})`]);
      }
    }
    if (e.time) {
      const c = e.time.calibration;
      rows.push(['per step', `${fmtDuration(e.time.seconds_per_step)} on ${c.threads} threads`]);
      rows.push(['to the end', `${fmtDuration(e.time.seconds_to_end)} (solver only; from ${c.steps} steps of ${c.particles_per_side}^n particles)`]);
    }
    result.replaceChildren(...rows.map(([k, v]) => {
      const div = document.createElement('div');
      const dt = document.createElement('dt');
      const dd = document.createElement('dd');
      dt.textContent = k;
      dd.textContent = v;
      dd.dataset.field = k;
      div.append(dt, dd);
      return div;
    }));
    result.hidden = false;
    if (e.admitted) showStatus('create-status', 'Estimate: the server would accept this run.', 'ok');
    else showStatus('create-status', `The server would refuse this run: ${e.refusal?.message ?? ''}`, 'error');
  } catch (e) {
    showStatus('create-status', errorText(e), 'error');
  } finally {
    button.disabled = false;
  }
}

// ---------------------------------------------------------------- scene schema

/** The products a preset's live analysis starts with: the live ones and the preset's own. */
function defaultProducts(preset) {
  return new Set([...(getPath(preset?.scene, 'analysis.products') ?? []), ...LIVE_PRODUCTS]);
}

/** The live-analysis fields of the form follow its *Live analysis* check box. */
function applyLiveChoice() {
  const live = $('create-live').checked;
  $('create-every').disabled = !live;
  for (const box of productBoxes()) box.disabled = !live;
}

/** The form's analysis-product check boxes (one per name the scene schema declares). */
function productBoxes() {
  return [...$('create-products').querySelectorAll('input[type=checkbox]')];
}

/** The product check boxes from the schema's names, keeping what was checked. */
function renderProductBoxes(node) {
  const names = node?.items?.enum;
  if (!Array.isArray(names)) return;
  const checked = new Set(productBoxes().filter((b) => b.checked).map((b) => b.value));
  const fresh = !productBoxes().length;
  $('create-products').title = node.description ?? '';
  $('create-products').replaceChildren(...names.map((name) => {
    const label = document.createElement('label');
    label.className = 'check';
    const box = document.createElement('input');
    box.type = 'checkbox';
    box.value = name;
    box.dataset.product = name;
    box.checked = (fresh ? defaultProducts(selectedPreset()) : checked).has(name);
    box.disabled = !$('create-live').checked;
    label.append(box, ` ${PRODUCT_LABELS[name] ?? name}`);
    return label;
  }));
}

/** The schema of a dotted scene field in the scene schema (GET /api/schema/scene), or null. */
function schemaNode(schema, path) {
  let node = schema;
  for (const key of path.split('.')) {
    const next = node?.properties?.[key] ??
      (typeof node?.additionalProperties === 'object' ? node.additionalProperties : undefined);
    if (!next) return null;
    node = next;
  }
  return node;
}

/**
 * Fits every form field that names a scene key (data-path) to the scene schema, the one
 * declaration of the scene (docs/scenes.md): the options of a select are the schema's names
 * (labels kept for names the page knows, the name itself for new ones), a number input takes
 * the schema's bounds and integer step, and every field the schema's description as its tooltip.
 */
function applySceneSchema(schema) {
  app.sceneSchema = schema;
  // The same schema validates the form's scene before it is sent (ajv, vendored; the server
  // validates again, so a page without it only loses the early message).
  if (typeof window.ajv7 === 'function') {
    app.validateScene = new window.ajv7({ strict: false, allErrors: false }).compile(schema);
  }
  renderProductBoxes(schemaNode(schema, 'analysis.products'));
  for (const el of document.querySelectorAll('[data-path]')) {
    const node = schemaNode(schema, el.dataset.path);
    if (!node) continue;
    if (node.description && !el.title) el.title = node.description;
    if (el.tagName === 'SELECT' && Array.isArray(node.enum)) {
      const current = el.value;  // kept: the schema may arrive after the form was filled
      const labels = new Map([...el.options].map((o) => [o.value, o.textContent]));
      const options = [];
      if (labels.has('')) options.push(['', labels.get('')]);
      for (const name of node.enum) options.push([name, labels.get(name) ?? name]);
      el.replaceChildren(...options.map(([value, label]) => {
        const o = document.createElement('option');
        o.value = value;
        o.textContent = label;
        return o;
      }));
      if (options.some(([value]) => value === current)) el.value = current;
    } else if (el.tagName === 'INPUT' && el.type === 'number') {
      const lower = node.minimum ?? node.exclusiveMinimum;
      const upper = node.maximum ?? node.exclusiveMaximum;
      if (lower !== undefined) el.min = String(lower);
      if (upper !== undefined) el.max = String(upper);
      if (node.type === 'integer') el.step = '1';
    }
  }
}

/** RFC 7396: `patch` merged into a copy of `target` (null removes a key). */
function mergePatch(target, patch) {
  if (patch === null || typeof patch !== 'object' || Array.isArray(patch)) return patch;
  const out = target !== null && typeof target === 'object' && !Array.isArray(target) ? { ...target } : {};
  for (const [key, value] of Object.entries(patch)) {
    if (value === null) delete out[key];
    else out[key] = mergePatch(out[key], value);
  }
  return out;
}

/**
 * Why the scene `document` does not conform to the scene schema, worded as the server words it
 * ("'kernel.diameter_over_spacing' must be <= 16"), or null (also when no validator is loaded).
 */
function sceneSchemaError(document) {
  if (!app.validateScene || app.validateScene(document)) return null;
  const e = app.validateScene.errors[0];
  let field = e.instancePath.slice(1).replace(/\/(\d+)(?=\/|$)/g, '[$1]').replaceAll('/', '.');
  if (e.keyword === 'additionalProperties') {
    field = field ? `${field}.${e.params.additionalProperty}` : e.params.additionalProperty;
    return `unknown key '${field}'`;
  }
  return `'${field || '(top level)'}' ${e.message}`;
}

async function loadSceneSchema() {
  try {
    applySceneSchema(await api.sceneSchema());
  } catch (e) {
    showStatus('create-status', `Could not load the scene schema: ${errorText(e)}`, 'error');
  }
}

// ---------------------------------------------------------------- selected run

function selectRun(id) {
  if (id === app.selectedId) return;
  if (app.stream) app.stream.close();
  app.stream = null;
  for (const url of Object.values(app.shownUrl)) if (url && url.startsWith('blob:')) URL.revokeObjectURL(url);
  Object.assign(app, {
    selectedId: id, summary: app.runs.find((r) => r.id === id) ?? null, detail: null,
    samples: [], analysis: [], stats: [], spectrum: null, latestStatistics: null, frames: [],
    reference: null, referenceWhy: null, referencePending: false, referenceRetry: { failures: 0, at: 0 },
    resolved: null, resolvedAvailable: false, resolvedAt: 0, availableAfterSpectrum: false,
    live: true, liveImage: {}, shownUrl: {}, progressHistory: [],
  });
  history.replaceState(null, '', `#run=${encodeURIComponent(id)}`);
  $('no-run').hidden = true;
  $('run-detail').hidden = false;
  for (const f of IMAGE_FIELDS) {
    const img = $(`img-${f}`);
    img.removeAttribute('src');
    delete img.dataset.step;
    setText(`cap-${f}`, 'no image yet');
  }
  showStatus('control-status', '');
  showStatus('param-status', '');
  setText('run-log', 'no log yet');
  $('run-log').dataset.lines = '0';
  refreshLog();
  $('run-files').replaceChildren();
  $('run-files').dataset.count = '0';
  refreshFiles();
  setText('cap-spectrum', 'no spectrum yet');
  $('resolved-table').replaceChildren();
  $('resolved-table').dataset.shells = '0';
  setText('cap-resolved', 'no reference run of this flow (docs/reference.md)');
  resetReferenceForm();
  setText('cap-stats', 'no statistics yet');
  ensureCharts();
  renderRunList();
  renderHeader();
  renderFrames();
  scheduleRedraw();
  app.stream = new RunStream(id, getToken(), {
    onState: onStreamState,
    onOpen: () => backfill(id),
    onMessage: (m) => onStreamMessage(id, m),
    onImage: (h, blob) => onImage(id, h, blob),
  });
}

function onStreamState({ state, attempt, delayMs, detail }) {
  const el = $('ws-state');
  el.dataset.state = state;
  const texts = {
    connecting: attempt ? `stream: connecting (attempt ${attempt + 1})` : 'stream: connecting',
    open: 'stream: open',
    closed: app.selectedId ? 'stream: closed' : 'stream: no run selected',
    reconnecting: `stream: closed${detail ? ` (${detail})` : ''} · reconnecting in ${(delayMs / 1000).toFixed(1)} s`,
  };
  el.textContent = texts[state] ?? `stream: ${state}`;
}

/** After each (re)connection: the history the stream does not repeat. */
async function backfill(id) {
  try {
    const [detail, series, frames, analysis] = await Promise.all([
      api.run(id), api.timeseries(id).catch(() => null), api.frames(id).catch(() => []),
      api.analysisHistory(id).catch(() => null),
    ]);
    if (id !== app.selectedId) return;
    applyDetail(detail);
    if (series) addTimeseries(series);
    if (analysis) addAnalysisHistory(analysis);
    addFrames(frames);
    // Only products the server says exist (a request for a missing one is a 404 that the
    // browser logs as an error).
    const available = detail.available ?? {};
    if (available.reference && !app.reference) loadReference(id);
    else if (!available.reference) app.referenceWhy = 'none for this case and Reynolds number (GET /api/runs/{id}/reference says why)';
    applyAvailable(id, available);
    if (available.spectrum) {
      const s = await api.spectrum(id).catch(() => null);
      if (s && id === app.selectedId) onSpectrum(s);
    }
    if (available.statistics) {
      const s = await api.statistics(id).catch(() => null);
      if (s && id === app.selectedId) onStatistics(s);
    }
    if (app.live) showLatestSavedFrames();
    scheduleRedraw();
  } catch (e) {
    if (id === app.selectedId && !isCancelled(e)) showStatus('control-status', `Could not load the run: ${errorText(e)}`, 'error');
  }
}

function applyDetail(detail) {
  if (!detail) return;
  app.detail = detail;
  mergeSummary(detail);
  fillParamForm(detail.scene ?? {});
  const changeable = Array.isArray(detail.changeable) ? detail.changeable : [];
  setText('param-changeable', changeable.length ? `Changeable while the run exists: ${changeable.join(', ')}.` : '');
}

function mergeSummary(s) {
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

function renderHeader() {
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
  const allowed = ALLOWED[s.state] ?? [];
  for (const b of document.querySelectorAll('.controls button[data-action]'))
    b.disabled = app.busy || !allowed.includes(b.dataset.action);
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

function deselectRun() {
  app.autoSelect = false;  // the user closed it (or it was deleted): none is picked for them
  if (app.stream) app.stream.close();
  app.stream = null;
  app.selectedId = null;
  app.summary = null;
  resetReferenceForm();  // its job goes on; the page stops polling it
  history.replaceState(null, '', location.pathname);
  $('run-detail').hidden = true;
  $('no-run').hidden = false;
  renderRunList();
}

async function deleteRun(id) {
  if (!window.confirm(`Delete run ${id} and all its files (time series, spectra, frames, checkpoints)?`)) return;
  app.busy = true;
  renderHeader();
  showStatus('control-status', 'delete…');
  // Nothing of the run may reach the server after it is gone (the reference, log and file
  // list refresh on their own); a refused delete loads them again.
  cancelRunRequests(id);
  try {
    await api.remove(id);
    app.runsGeneration += 1;
    app.runs = app.runs.filter((r) => r.id !== id);
    app.busy = false;
    deselectRun();
  } catch (e) {
    app.busy = false;
    if (app.selectedId === id) {
      app.selectedId = null;
      selectRun(id);
    }
    showStatus('control-status', `delete refused: ${errorText(e)}`, 'error');
    renderHeader();
  }
}

async function onAction(event) {
  const verb = event.currentTarget.dataset.action;
  const id = app.selectedId;
  if (!id) return;
  if (verb === 'delete') {
    await deleteRun(id);
    return;
  }
  app.busy = true;
  renderHeader();
  showStatus('control-status', `${verb}…`);
  try {
    const summary = await api.action(id, verb);
    mergeSummary(summary);
    showStatus('control-status', `${verb}: now ${summary.state}`, 'ok');
  } catch (e) {
    showStatus('control-status', `${verb} refused: ${errorText(e)}`, 'error');
  } finally {
    app.busy = false;
    renderHeader();
  }
}

// ---------------------------------------------------------------- stream messages

function onStreamMessage(id, m) {
  if (id !== app.selectedId || !m || typeof m !== 'object') return;
  switch (m.type) {
    case 'hello':
      applyDetail(m.run);
      // Lines written between the log's fetch at selection and this stream's start (a run that
      // failed meanwhile sends no 'state' message to it) are read now.
      refreshLog();
      break;
    case 'state':
      mergeSummary({ id, state: m.state, reason: m.reason ?? '' });
      pollSoon();
      refreshLog();
      refreshFiles();
      break;
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
      break;
    case 'error':
      showStatus('param-status', errorText(new ApiError(m.error?.status ?? 0, m.error?.message ?? 'error', m.error?.field)), 'error');
      break;
    default:
      break;  // newer message types: ignored
  }
}

/** The end of the selected run's run.log into the log panel, kept scrolled to the bottom when
 *  the reader is there. */
async function refreshLog() {
  const id = app.selectedId;
  if (!id) return;
  let text;
  try {
    text = await api.log(id, LOG_LINES);
  } catch {
    return;  // the run list's poll reports the connection state
  }
  if (id !== app.selectedId) return;
  const pre = $('run-log');
  const atBottom = pre.scrollTop + pre.clientHeight >= pre.scrollHeight - 4;
  const lines = text ? text.replace(/\n$/, '').split('\n').length : 0;
  pre.textContent = text || 'no log yet';
  pre.dataset.lines = String(lines);
  if (atBottom) pre.scrollTop = pre.scrollHeight;
}

/** The run directory's files as download links: top-level files, then one collapsible group per
 *  subdirectory with its count and size. */
async function refreshFiles() {
  const id = app.selectedId;
  if (!id) return;
  let files;
  try {
    files = await api.files(id);
  } catch {
    return;  // the run list's poll reports the connection state
  }
  if (id !== app.selectedId || !Array.isArray(files)) return;
  const link = (f, text) => {
    const li = document.createElement('li');
    const a = document.createElement('a');
    a.href = f.url;
    a.download = f.path.split('/').pop();
    a.textContent = text;
    li.append(a, ` ${fmtBytes(f.bytes)}`);
    return li;
  };
  const top = document.createElement('ul');
  top.className = 'files';
  if (files.length) {
    const whole = link({ url: api.archiveUrl(id), path: `${id}.tar`, bytes: files.reduce((n, f) => n + f.bytes, 0) },
      `the whole run as one archive (${id}.tar, ${files.length} files)`);
    whole.id = 'run-archive';
    top.append(whole);
  }
  const groups = new Map();
  for (const f of files) {
    const slash = f.path.indexOf('/');
    if (slash < 0) top.append(link(f, f.path));
    else {
      const dir = f.path.slice(0, slash);
      if (!groups.has(dir)) groups.set(dir, []);
      groups.get(dir).push(f);
    }
  }
  const parts = [top];
  for (const [dir, list] of groups) {
    const details = document.createElement('details');
    const summary = document.createElement('summary');
    summary.textContent = `${dir}/ (${list.length} file${list.length === 1 ? '' : 's'}, ${fmtBytes(list.reduce((n, f) => n + f.bytes, 0))})`;
    const ul = document.createElement('ul');
    ul.className = 'files';
    ul.append(...list.map((f) => link(f, f.path.slice(dir.length + 1))));
    details.append(summary, ul);
    parts.push(details);
  }
  const box = $('run-files');
  box.replaceChildren(...(files.length ? parts : [Object.assign(document.createElement('p'), { className: 'muted', textContent: 'no files yet' })]));
  box.dataset.count = String(files.length);
}

let pollSoonTimer = null;
function pollSoon() {
  // A state change also changes the run list; refresh it without waiting for the next poll.
  if (pollSoonTimer) return;
  pollSoonTimer = setTimeout(async () => {
    pollSoonTimer = null;
    try {
      app.runs = await api.runs();
      renderRunList();
    } catch {
      // the regular poll reports the connection state
    }
  }, 100);
}

function toSample(s) {
  return {
    time: finite(s.time), step: s.step, kinetic_energy: finite(s.kinetic_energy),
    dissipation: finite(s.dissipation),
  };
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
    mergeSummary({
      id: app.selectedId, time: last.time, step: last.step,
      progress: end > 0 ? Math.min(1, last.time / end) : app.summary.progress,
    });
  }
  scheduleRedraw();
}

/** A column of a {columns, data} answer (time series, analysis, reference) by name; [] if absent. */
function columnOf(answer) {
  const columns = Array.isArray(answer?.columns) ? answer.columns : [];
  const data = Array.isArray(answer?.data) ? answer.data : [];
  return (name) => data[columns.indexOf(name)] ?? [];
}

function addTimeseries(series) {
  const col = columnOf(series);
  const time = col('time');
  const step = col('step');
  const energy = col('kinetic_energy');
  const dissipation = col('dissipation');
  const rows = [];
  for (let i = 0; i < time.length; i++)
    rows.push({ time: time[i], step: step[i], kinetic_energy: energy[i], dissipation: dissipation[i] });
  addSamples(rows);
}

/** The run's reference curve (GET reference): the analytic 2D decay, the 3D DNS or the laminar
 *  Kolmogorov flow, or why none; to `until` seconds if given (redraw asks again as the run goes
 *  on, so that the plotted span is sampled finely). */
async function loadReference(id, until) {
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

/** The analysis frames written before the page connected (GET analysis): the dissipation
 *  estimates and the sub-filter stress over the whole run, also after a reload or a restart. */
function addAnalysisHistory(history) {
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

/** The resolved scales against the reference run of the flow, at most every 2 s of wall time. */
async function loadResolved(id) {
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

// ---------------------------------------------------------------- spectral reference jobs

/** What the run detail says exists for the resolved scales: the table when a reference run of
 *  the flow exists; else, once the run has spectra, the form that computes one. */
function applyAvailable(id, available) {
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
async function refreshAvailable(id) {
  const detail = await api.run(id).catch(() => null);
  if (detail && id === app.selectedId) applyAvailable(id, detail.available ?? {});
}

function resetReferenceForm() {
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

async function onEstimateReference() {
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

async function onComputeReference(event) {
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
    button.disabled = REFERENCE_ACTIVE.has(app.referenceJob?.state);  // one job of a run at a time
  }
}

/** Stop a queued or running job (it writes a checkpoint), resume a stopped or failed one. */
async function onToggleReference() {
  const id = app.selectedId;
  const job = app.referenceJob;
  if (!job) return;
  const button = $('reference-toggle');
  button.disabled = true;
  try {
    const next = await api.referenceAction(job.id, REFERENCE_ACTIVE.has(job.state) ? 'stop' : 'resume');
    if (id === app.selectedId) followReferenceJob(id, next);
  } catch (e) {
    showStatus('reference-status', errorText(e), 'error');
  } finally {
    button.disabled = false;
  }
}

/** Shows a job of the selected run's flow, polls it while it is queued or running, and shows the
 *  resolved scales once it is done. */
function followReferenceJob(id, job) {
  clearTimeout(app.referenceJobTimer);
  app.referenceJob = job;
  showReferenceJob(job);
  if (REFERENCE_ACTIVE.has(job.state)) {
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
  $('reference-compute').disabled = REFERENCE_ACTIVE.has(job.state);
  const progress = $('reference-progress');
  progress.hidden = job.state !== 'running';
  progress.value = job.progress;
  const toggle = $('reference-toggle');
  toggle.hidden = job.state === 'done';
  toggle.textContent = REFERENCE_ACTIVE.has(job.state) ? 'Stop' : 'Resume';
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

function onSpectrum(m) {
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

function onStatistics(m) {
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

// ---------------------------------------------------------------- images and frames

function onImage(id, header, blob) {
  if (id !== app.selectedId || !IMAGE_FIELDS.includes(header.field)) {
    if (id === app.selectedId && header.file) addFrames([header]);
    return;
  }
  if (header.file) addFrames([header]);
  app.liveImage[header.field] = { blob, header };
  if (app.live) showLiveImage(header.field);
}

function showLiveImage(field) {
  const pending = app.liveImage[field];
  if (!pending) return;
  app.liveImage[field] = null;
  showImage(field, URL.createObjectURL(pending.blob), pending.header, 'live');
}

function showImage(field, url, header, how) {
  const img = $(`img-${field}`);
  const previous = app.shownUrl[field];
  app.shownUrl[field] = url;
  const release = () => {
    if (previous && previous !== url && previous.startsWith('blob:')) URL.revokeObjectURL(previous);
  };
  img.onload = () => {
    release();
    img.dataset.step = String(header.step ?? '');
    img.dataset.time = String(header.time ?? '');
    setText(`cap-${field}`, `t = ${formatNumber(header.time)} s, step ${header.step ?? '–'} (${how})`);
  };
  img.onerror = () => {
    release();
    setText(`cap-${field}`, 'image could not be decoded');
  };
  img.src = url;
}

function addFrames(list) {
  if (!Array.isArray(list)) return;
  let changed = false;
  for (const f of list) {
    if (!f || !f.file || !f.field) continue;
    let group = app.frames.find((g) => g.step === f.step);
    if (!group) {
      group = { time: f.time, step: f.step, files: {} };
      app.frames.push(group);
    }
    if (group.files[f.field] !== f.file) {
      group.files[f.field] = f.file;
      changed = true;
    }
  }
  if (changed) {
    app.frames.sort((a, b) => a.step - b.step);
    renderFrames();
  }
}

function renderFrames() {
  const scrubber = $('frame-scrubber');
  const n = app.frames.length;
  scrubber.disabled = n === 0;
  scrubber.max = String(Math.max(0, n - 1));
  if (app.live) scrubber.value = String(Math.max(0, n - 1));
  $('btn-live').setAttribute('aria-pressed', app.live ? 'true' : 'false');
  $('btn-live').disabled = app.live;
  const label = $('frame-label');
  if (app.live) label.textContent = n ? `live · ${n} saved` : 'live · no saved frames';
  else {
    const g = app.frames[Number(scrubber.value)];
    label.textContent = g ? `t = ${formatNumber(g.time)} s (${Number(scrubber.value) + 1}/${n})` : '–';
  }
  scrubber.setAttribute('aria-valuetext', label.textContent);
}

function showFrame(index) {
  const g = app.frames[index];
  if (!g) return;
  for (const f of IMAGE_FIELDS) {
    if (g.files[f]) showImage(f, api.frameUrl(app.selectedId, g.files[f]), g, 'saved');
  }
}

/** Newest saved frame of each field, until a live image replaces it. */
function showLatestSavedFrames() {
  for (const f of IMAGE_FIELDS) {
    if (app.shownUrl[f]) continue;
    const g = [...app.frames].reverse().find((x) => x.files[f]);
    if (g) showImage(f, api.frameUrl(app.selectedId, g.files[f]), g, 'saved');
  }
}

function onScrub() {
  app.live = false;
  renderFrames();
  showFrame(Number($('frame-scrubber').value));
}

function goLive() {
  app.live = true;
  renderFrames();
  for (const f of IMAGE_FIELDS) showLiveImage(f);
}

// ---------------------------------------------------------------- plots

function ensureCharts() {
  if (app.charts || !plottingAvailable()) return;
  app.charts = {
    energy: energyChart($('chart-energy')),
    dissipation: dissipationChart($('chart-dissipation')),
    spectrum: spectrumChart($('chart-spectrum')),
    stats: statisticsChart($('chart-stats')),
  };
}

function scheduleRedraw() {
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

/** Overlays (or removes) a run's time series and latest spectrum on the plots. */
async function toggleCompared(id, on) {
  if (!on) {
    app.compared.delete(id);
    scheduleRedraw();
    return;
  }
  const run = app.runs.find((r) => r.id === id);
  const entry = { label: run?.name || id, time: [], energy: [], dissipation: [], spectrum: null };
  app.compared.set(id, entry);
  try {
    const [series, detail] = await Promise.all([api.timeseries(id), api.run(id)]);
    const col = columnOf(series);
    Object.assign(entry, { time: col('time'), energy: col('kinetic_energy'), dissipation: col('dissipation') });
    if (detail.available?.spectrum) entry.spectrum = await api.spectrum(id).catch(() => null);
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
  for (const chart of [c.energy, c.dissipation, c.spectrum]) chart.setExtraSeries(labels);
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

  // Only the selected run's spectrum: none yet (a run just selected) empties the plot.
  const s = app.spectrum;
  const hasSpectrum = s && Array.isArray(s.k) && Array.isArray(s.energy);
  // The reference's E(k) at the latest compared time, dashed (GET resolved).
  // Shells the reference leaves empty (round-off, 10⁻³⁰ of its peak) are not drawn: they
  // would stretch the log axis over tens of decades.
  const refSpectrum = hasSpectrum ? app.resolved?.reference_spectrum : null;
  const refPeak = refSpectrum ? Math.max(...refSpectrum.energy) : 0;
  const refKeep = refSpectrum
    ? refSpectrum.k.map((k, i) => i).filter((i) => refSpectrum.k[i] > 0 && refSpectrum.energy[i] > 1e-12 * refPeak)
    : [];
  const own = mergeOnTime(hasSpectrum ? spectrumData(s.k, s.energy) : spectrumData([], []),
    { x: refKeep.map((i) => refSpectrum.k[i]), ys: [refKeep.map((i) => refSpectrum.energy[i])] });
  $('chart-spectrum').dataset.referencePoints = String(refKeep.length);
  const d = withCompared(own, (r) => {
    const k = r.spectrum?.k ?? [];
    const e = r.spectrum?.energy ?? [];
    const keep = k.map((kk, i) => i).filter((i) => k[i] > 0);
    return { x: keep.map((i) => k[i]), y: keep.map((i) => (e[i] > 0 ? e[i] : null)) };
  });
  c.spectrum.setData(d.x, d.ys);
  c.spectrum.setMarkers(hasSpectrum ? [
    { x: s.kernel_wavenumber, label: 'k_kern = 2π/D_K', colour: '#b22222', row: 0 },
    { x: s.resolution_wavenumber, label: 'k_res = π/Δl', colour: '#555555', row: 1 },
  ] : []);
  c.stats.setData(app.stats.map((p) => p.time), [app.stats.map((p) => p.max), app.stats.map((p) => p.mean)]);
}

// ---------------------------------------------------------------- live parameters

function fillParamForm(scene) {
  $('p-chi').disabled = scene?.case !== 'kolmogorov2d';  // the forcing of the Kolmogorov flow
  for (const input of $('param-form').querySelectorAll('[data-path]')) {
    let value = getPath(scene, input.dataset.path);
    if (input.tagName === 'SELECT' && (value === undefined || value === null)) value = 'log';
    const text = value === undefined || value === null ? '' : String(value);
    // Keep what the user is typing; refresh the rest.
    if (document.activeElement !== input && (input.value === input.dataset.initial || input.dataset.initial === undefined))
      input.value = text;
    input.dataset.initial = text;
  }
}

function buildParameterPatch() {
  const patch = {};
  for (const input of $('param-form').querySelectorAll('[data-path]')) {
    if (input.value === input.dataset.initial) continue;
    let v = readInput(input);
    if (v === undefined) {
      if (!('nullable' in input.dataset)) continue;
      v = null;  // an empty bound goes back to the automatic (percentile) range
    }
    setPath(patch, input.dataset.path, v);
  }
  return patch;
}

async function onApplyParameters(event) {
  event.preventDefault();
  const id = app.selectedId;
  if (!id) return;
  let patch;
  try {
    patch = buildParameterPatch();
  } catch (e) {
    showStatus('param-status', e.message, 'error');
    return;
  }
  if (!Object.keys(patch).length) {
    showStatus('param-status', 'Nothing changed.');
    return;
  }
  $('param-apply').disabled = true;
  showStatus('param-status', 'Applying…');
  try {
    const r = await api.patchParameters(id, patch);
    showStatus('param-status', `Changed: ${(r.changed ?? []).join(', ') || 'nothing'}${r.effective ? ` (effective ${r.effective})` : ''}.`, 'ok');
    for (const input of $('param-form').querySelectorAll('[data-path]')) input.dataset.initial = input.value;
  } catch (e) {
    showStatus('param-status', `Rejected: ${errorText(e)}`, 'error');
  } finally {
    $('param-apply').disabled = false;
  }
}

function resetParamForm() {
  for (const input of $('param-form').querySelectorAll('[data-path]')) input.value = input.dataset.initial ?? '';
  showStatus('param-status', '');
}

// ---------------------------------------------------------------- start-up

function onTokenSave(event) {
  event.preventDefault();
  setToken($('token').value.trim());
  if (app.stream) app.stream.reconnectNow(getToken());
  showStatus('create-status', getToken() ? 'Token saved in this browser.' : 'Token cleared.', 'ok');
}

function main() {
  if (!plottingAvailable()) {
    const banner = $('page-error');
    banner.hidden = false;
    banner.textContent = 'The plotting library is missing (web/vendor/uPlot.iife.min.js): build the ' +
      'CMake target web_assets (needs npm). Run control, images and parameters still work.';
  }
  $('token').value = getToken();
  $('token-form').addEventListener('submit', onTokenSave);
  listenToRunList(selectRun, toggleCompared);
  $('create-form').addEventListener('submit', onCreate);
  $('create-estimate').addEventListener('click', onEstimate);
  $('btn-clone').addEventListener('click', cloneSelectedRun);
  $('files-refresh').addEventListener('click', refreshFiles);
  $('reference-form').addEventListener('submit', onComputeReference);
  $('reference-estimate').addEventListener('click', onEstimateReference);
  $('reference-toggle').addEventListener('click', onToggleReference);
  $('create-preset').addEventListener('change', fillCreateForm);
  $('create-live').addEventListener('change', applyLiveChoice);
  for (const b of document.querySelectorAll('.controls button[data-action]')) b.addEventListener('click', onAction);
  $('frame-scrubber').addEventListener('input', onScrub);
  $('btn-live').addEventListener('click', goLive);
  $('param-form').addEventListener('submit', onApplyParameters);
  $('param-reset').addEventListener('click', resetParamForm);
  window.addEventListener('hashchange', () => {
    const id = new URLSearchParams(location.hash.slice(1)).get('run');
    if (id && app.runs.some((r) => r.id === id)) selectRun(id);
  });
  api.health().then((h) => {
    $('api-state').title = `sphles ${h.version ?? ''} — REST API polled every ${POLL_MS / 1000} s`;
  }).catch(() => {});
  loadSceneSchema();
  loadPresets();
  pollRuns();
  setInterval(() => {
    if (!document.hidden && app.summary && ACTIVE.has(app.summary.state)) refreshLog();
  }, LOG_POLL_MS);
}

main();
