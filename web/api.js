// SPDX-License-Identifier: GPL-3.0-or-later
// @ts-check
// REST client of the sphles server (docs/api.md). Every call goes to the origin that served the
// page; the optional token (stored in localStorage) is sent as `Authorization: Bearer`.

const TOKEN_KEY = 'sphles.token';

export function getToken() {
  try {
    return localStorage.getItem(TOKEN_KEY) || '';
  } catch {
    return '';  // storage disabled: no token
  }
}

/** @param {string} token */
export function setToken(token) {
  try {
    if (token) localStorage.setItem(TOKEN_KEY, token);
    else localStorage.removeItem(TOKEN_KEY);
  } catch {
    // storage disabled: the token lives for this page only
  }
}

/** An error answer of the server: {"error": {"status", "message", "field"}}. */
export class ApiError extends Error {
  /**
   * @param {number} status
   * @param {string} message
   * @param {string | null | undefined} field
   * @param {boolean} [cancelled] the page cancelled the request (cancelRunRequests)
   */
  constructor(status, message, field, cancelled = false) {
    super(message);
    this.name = 'ApiError';
    this.status = status;
    this.field = field ?? null;
    this.cancelled = cancelled;
  }
}

// Types (checked, not run: the ctest typed_client runs `tsc --strict --checkJs` on this file
// against the types openapi-typescript generates from the served OpenAPI document, so a call
// whose path, method, body or answer the document does not describe fails the build's tests).
/** @typedef {import('sphles-openapi').paths} Paths */
/** @typedef {'get' | 'post' | 'patch' | 'delete'} Method */
/**
 * The methods the OpenAPI document describes for path P.
 * @template {keyof Paths} P
 * @typedef {{ [M in Method]: Paths[P][M] extends undefined ? never : M }[Method]} MethodOf
 */
/**
 * The JSON body of the operation's success answer (200 or 201).
 * @template {keyof Paths} P
 * @template {MethodOf<P>} M
 * @typedef {Paths[P][M] extends { responses: infer R }
 *   ? R extends { 200: { content: { 'application/json': infer B } } } ? B
 *   : R extends { 201: { content: { 'application/json': infer B } } } ? B
 *   : R extends { 200: { content: { 'text/plain': infer T } } } ? T
 *   : unknown
 *   : never} Reply
 */
/**
 * The JSON request body of the operation (undefined if it has none).
 * @template {keyof Paths} P
 * @template {MethodOf<P>} M
 * @typedef {Paths[P][M] extends { requestBody?: { content: { 'application/json': infer B } } }
 *   ? B : undefined} Body
 */

/** @typedef {Body<'/api/references', 'post'>} ReferenceRequest */
/** @typedef {import('sphles-openapi').components['schemas']['ReferenceJob']} ReferenceJob */

/**
 * One operation of the API: `path` is a path of the OpenAPI document ("/api/runs/{id}"), its
 * {parameters} filled from `params`.
 * @template {keyof Paths} P
 * @template {MethodOf<P>} M
 * @param {M} method
 * @param {P} path
 * @param {{ params?: Record<string, string>, query?: Record<string, string | number>,
 *           body?: Body<P, M>, text?: boolean, timeoutMs?: number }} [options]
 * @returns {Promise<Reply<P, M>>}
 */
function call(method, path, { params = {}, query, body, text = false, timeoutMs = 0 } = {}) {
  let target = String(path).replace(/\{(\w+)\}/g, (_, name) => encodeURIComponent(params[name] ?? ''));
  if (query) target += `?${new URLSearchParams(Object.entries(query).map(([k, v]) => [k, String(v)]))}`;
  return request(method.toUpperCase(), target, body, { text, timeoutMs });
}

/** Requests under way, by their path: those of a run are cancelled before it is deleted, so that
 *  none reaches the server after the run is gone (a 404 the user did not cause). */
/** @type {Map<AbortController, string>} */
const inFlight = new Map();

/** Cancels the requests under way for run `id` (its summary and every path below it); they
 *  reject with an ApiError of status 0 and `cancelled` set.
 *  @param {string} id */
export function cancelRunRequests(id) {
  const own = runPath(id);
  for (const [controller, path] of inFlight)
    if (path === own || path.startsWith(`${own}/`) || path.startsWith(`${own}?`)) controller.abort();
}

/**
 * @param {string} method
 * @param {string} path
 * @param {unknown} body
 * @param {{ text?: boolean, timeoutMs?: number }} [options] timeoutMs > 0: the request (answer
 *   and body) is abandoned after so long, rejecting with status 0, so that a poll never waits
 *   for ever on an answer that does not come
 * @returns {Promise<any>}
 */
async function request(method, path, body, { text: asText = false, timeoutMs = 0 } = {}) {
  /** @type {Record<string, string>} */
  const headers = { Accept: asText ? 'text/plain' : 'application/json' };
  const token = getToken();
  if (token) headers.Authorization = `Bearer ${token}`;
  const controller = new AbortController();
  /** @type {RequestInit} */
  const init = { method, headers, cache: 'no-store', signal: controller.signal };
  if (body !== undefined) {
    headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  let response;
  let text;
  let timedOut = false;
  const timer = timeoutMs > 0 ? setTimeout(() => { timedOut = true; controller.abort(); }, timeoutMs) : 0;
  inFlight.set(controller, path);
  try {
    response = await fetch(path, init);
    text = await response.text();
  } catch (e) {
    if (timedOut) throw new ApiError(0, `no answer within ${timeoutMs / 1000} s`, null);
    if (controller.signal.aborted) throw new ApiError(0, 'request cancelled', null, true);
    throw new ApiError(0, `server unreachable (${e instanceof Error ? e.message : e})`, null);
  } finally {
    clearTimeout(timer);
    inFlight.delete(controller);
  }
  if (asText && response.ok) return text;
  let json = null;
  if (text) {
    try {
      json = JSON.parse(text);
    } catch {
      if (response.ok) throw new ApiError(response.status, `malformed JSON from ${path}`, null);
    }
  }
  if (!response.ok) {
    const err = json && json.error;
    const message = err && err.message ? err.message : `${response.status} ${response.statusText}`;
    throw new ApiError(response.status, message, err ? err.field : null);
  }
  return json;
}

/** Rows of a run's time series the plots load at once; longer histories come decimated by the
 * server (first and last rows kept), so that a run of days still shows its whole history. */
const HISTORY_POINTS = 20000;

/** @param {string} id */
const ofRun = (id) => ({ params: { id } });
/** @param {string} id */
const decimated = (id) => ({ params: { id }, query: { max_points: HISTORY_POINTS } });
/** @param {string} id */
const runPath = (id) => `/api/runs/${encodeURIComponent(id)}`;

export const api = {
  health: () => call('get', '/api/health'),
  presets: () => call('get', '/api/presets'),
  /** The scene files the server offers beside the presets: {scenes: [...], skipped: [...]}. */
  scenes: () => call('get', '/api/scenes'),
  sceneSchema: () => call('get', '/api/schema/scene'),
  /** The run list (polled every few seconds): abandoned after 4 s, so that the next poll runs. */
  runs: () => call('get', '/api/runs', { timeoutMs: 4000 }),
  /** @param {string} id */
  run: (id) => call('get', '/api/runs/{id}', ofRun(id)),
  /** @param {Body<'/api/runs', 'post'>} body */
  create: (body) => call('post', '/api/runs', { body }),
  /**
   * What a create request would need and take on the server's machine (creates nothing).
   * @param {Body<'/api/estimate', 'post'>} body
   */
  estimate: (body) => call('post', '/api/estimate', { body }),
  /**
   * @param {string} id
   * @param {'start' | 'pause' | 'resume' | 'stop'} verb
   */
  action: (id, verb) => call('post', `/api/runs/{id}/${verb}`, ofRun(id)),
  /** @param {string} id */
  remove: (id) => call('delete', '/api/runs/{id}', ofRun(id)),
  /**
   * @param {string} id
   * @param {Body<'/api/runs/{id}/parameters', 'patch'>} patch
   */
  patchParameters: (id, patch) => call('patch', '/api/runs/{id}/parameters', { ...ofRun(id), body: patch }),
  /** @param {string} id */
  timeseries: (id) => call('get', '/api/runs/{id}/timeseries', decimated(id)),
  /**
   * Every file of the run directory: [{path, bytes, modified, url}].
   * @param {string} id
   */
  files: (id) => call('get', '/api/runs/{id}/files', ofRun(id)),
  /**
   * The run's saved frames of a field as a WebM video (movies/FIELD.webm): {path, url, frames, …}.
   * Encoding takes seconds on the server: no timeout.
   * @param {string} id
   * @param {Body<'/api/runs/{id}/movies', 'post'>} body
   */
  movie: (id, body) => call('post', '/api/runs/{id}/movies', { ...ofRun(id), body }),
  /**
   * A text file in a subdirectory of the run as GET files lists it (spectra/index.csv, a
   * spectrum's E_t….csv), as text.
   * @param {string} id
   * @param {string} dir
   * @param {string} name
   */
  runFileText: (id, dir, name) => call('get', '/api/runs/{id}/files/{dir}/{name}',
    { params: { id, dir, name }, text: true }),
  /**
   * The run's reference e_v(t) and -de_v/dt (404 with the reason when it has none), to its end
   * time or to `until` seconds if earlier.
   * @param {string} id
   * @param {number} [until]
   */
  reference: (id, until) => call('get', '/api/runs/{id}/reference',
    until === undefined ? ofRun(id) : { params: { id }, query: { until } }),
  /**
   * The run's resolved scales against the reference run of its flow (SPEC §9): E_res, the
   * shell ratios, the energy above k_kern, and the reference's E(k) at the latest time.
   * @param {string} id
   */
  resolved: (id) => call('get', '/api/runs/{id}/resolved', ofRun(id)),
  /** The spectral reference jobs of the server, oldest first. */
  references: () => call('get', '/api/references'),
  /**
   * What the spectral reference of a run's flow would need (POST /api/references with dry_run):
   * memory, steps, checkpoint size and whether the server admits it; creates nothing.
   * @param {ReferenceRequest} body
   */
  estimateReference: (body) => call('post', '/api/references', { body: { ...body, dry_run: true } }),
  /**
   * Starts computing it: the job, queued (201; the document's 200 is the dry run's estimate).
   * @param {ReferenceRequest} body
   * @returns {Promise<ReferenceJob>}
   */
  computeReference: (body) =>
    /** @type {Promise<ReferenceJob>} */ (/** @type {unknown} */ (call('post', '/api/references', { body }))),
  /** @param {string} id a reference job's id */
  referenceJob: (id) => call('get', '/api/references/{id}', { params: { id } }),
  /**
   * @param {string} id a reference job's id
   * @param {'stop' | 'resume'} verb
   */
  referenceAction: (id, verb) => call('post', `/api/references/{id}/${verb}`, { params: { id } }),
  /**
   * Every analysis frame's scalars (stats/snapshots.csv), decimated as the time series.
   * @param {string} id
   */
  analysisHistory: (id) => call('get', '/api/runs/{id}/analysis', decimated(id)),
  /** @param {string} id */
  spectrum: (id) => call('get', '/api/runs/{id}/spectrum', ofRun(id)),
  /** @param {string} id */
  statistics: (id) => call('get', '/api/runs/{id}/statistics', ofRun(id)),
  /**
   * The last `lines` lines of the run's run.log, as text.
   * @param {string} id
   * @param {number} lines
   */
  log: (id, lines) => call('get', '/api/runs/{id}/log', { params: { id }, query: { lines }, text: true }),
  /** @param {string} id */
  frames: (id) => call('get', '/api/runs/{id}/frames', ofRun(id)),
  /**
   * @param {string} id
   * @param {string} file
   */
  frameUrl: (id, file) => `${runPath(id)}/frames/${encodeURIComponent(file)}`,
  /**
   * The whole run directory as one tar archive (GET /api/runs/{id}/archive).
   * @param {string} id
   */
  archiveUrl: (id) => `${runPath(id)}/archive`,
  /**
   * @param {string} id
   * @param {string} field
   */
  imageUrl: (id, field) => `${runPath(id)}/images/${encodeURIComponent(field)}`,
};
