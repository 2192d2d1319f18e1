// SPDX-License-Identifier: GPL-3.0-or-later
// Run creation: the preset form (a patch over the preset's scene), Clone…, the estimate before a
// run is created, and the form fitted to the scene schema (GET /api/schema/scene).

import { api } from './api.js';
import { formatNumber } from './charts.js';
import {
  $, app, showStatus, errorText, getPath, setPath, fmtDuration, fmtBytes, readInput,
} from './state.js';
import { renderRunList } from './runs.js';
import { selectRun } from './run_view.js';

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

export async function loadPresets() {
  let presets = [];
  try {
    presets = await api.presets();
  } catch (e) {
    showStatus('create-status', `Could not load presets: ${errorText(e)}`, 'error');
  }
  app.presets = Array.isArray(presets) ? presets.slice() : [];
  // The scene files (scenes/ of the server) after the presets: each is a whole scene document,
  // created as {scene} like a clone. A server without them offers the presets alone.
  const scenes = await api.scenes().catch(() => null);
  for (const s of scenes?.scenes ?? [])
    app.presets.push({ ...s, builtinScene: true, description: `scenes/${s.file}: ${s.description}` });
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
export async function cloneSelectedRun() {
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

export function fillCreateForm() {
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
      // The live images are the slices rendered: the fields the server renders live, sliced
      // beside what the preset slices.
      const rendered = liveDefault(preset, 'render.fields');
      const sliced = getPath(preset.scene, 'analysis.slice.fields') ?? [];
      patch.analysis.slice = { fields: [...new Set([...sliced, ...rendered])] };
      patch.render = { fields: rendered, combined: false };
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

export async function onCreate(event) {
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

/** The form's run, estimated by the server before it is created (POST /api/estimate). */
export async function onEstimate() {
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
      if (e.time.frames > 0) {
        rows.push(['per analysis time', `${fmtDuration(e.time.analysis_seconds_per_frame)} analysis, ${fmtDuration(e.time.render_seconds_per_frame)} rendering`]);
      }
      rows.push(['to the end', `${fmtDuration(e.time.seconds_to_end)} (solver ${fmtDuration(e.time.solver_seconds)} from ${c.steps} steps of ${c.particles_per_side}^n particles${e.time.frames > 0 ? `; ${e.time.frames} analysis times beside it` : ''}; packing ${e.time.packing_seconds > 0 ? fmtDuration(e.time.packing_seconds) : 'none (off or cached)'})`]);
    }
    // What makes the answer meaningless although the run would run (sim/scene_warnings.hpp).
    for (const w of e.warnings ?? []) rows.unshift([`warning: ${w.field}`, w.message]);
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
    if (e.admitted && e.warnings?.length) {
      showStatus('create-status', `The server would accept this run, but: ${e.warnings[0].message}`, 'error');
    } else if (e.admitted) showStatus('create-status', 'Estimate: the server would accept this run.', 'ok');
    else showStatus('create-status', `The server would refuse this run: ${e.refusal?.message ?? ''}`, 'error');
  } catch (e) {
    showStatus('create-status', errorText(e), 'error');
  } finally {
    button.disabled = false;
  }
}

// ---------------------------------------------------------------- scene schema

/**
 * The server's live defaults at `path` of a preset's scene (control/run_manager.cpp,
 * with_live_defaults): GET /api/presets gives each preset's whole scene with them. A clone has
 * its run's scene, which may have none (a run made without live analysis): then the presets'.
 */
function liveDefault(preset, path) {
  const own = getPath(preset?.scene, path);
  if (Array.isArray(own) && own.length) return own;
  return getPath(app.presets.find((p) => !p.clone)?.scene, path) ?? [];
}

/** The products a preset's live analysis starts with: the server's live ones with the preset's. */
function defaultProducts(preset) {
  return new Set(liveDefault(preset, 'analysis.products'));
}

/** The live-analysis fields of the form follow its *Live analysis* check box. */
export function applyLiveChoice() {
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

export async function loadSceneSchema() {
  try {
    applySceneSchema(await api.sceneSchema());
  } catch (e) {
    showStatus('create-status', `Could not load the scene schema: ${errorText(e)}`, 'error');
  }
}
