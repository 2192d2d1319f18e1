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
  constructor(status, message, field) {
    super(message);
    this.name = 'ApiError';
    this.status = status;
    this.field = field ?? null;
  }
}

async function request(method, path, body, { text: asText = false } = {}) {
  const headers = { Accept: asText ? 'text/plain' : 'application/json' };
  const token = getToken();
  if (token) headers.Authorization = `Bearer ${token}`;
  const init = { method, headers, cache: 'no-store' };
  if (body !== undefined) {
    headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  let response;
  try {
    response = await fetch(path, init);
  } catch (e) {
    throw new ApiError(0, `server unreachable (${e.message})`, null);
  }
  const text = await response.text();
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

const run = (id) => `/api/runs/${encodeURIComponent(id)}`;

/** Rows of a run's time series the plots load at once; longer histories come decimated by the
 * server (first and last rows kept), so that a run of days still shows its whole history. */
const HISTORY_POINTS = 20000;

export const api = {
  health: () => request('GET', '/api/health'),
  presets: () => request('GET', '/api/presets'),
  sceneSchema: () => request('GET', '/api/schema/scene'),
  runs: () => request('GET', '/api/runs'),
  run: (id) => request('GET', run(id)),
  create: (body) => request('POST', '/api/runs', body),
  /** What a create request would need and take on the server's machine (creates nothing). */
  estimate: (body) => request('POST', '/api/estimate', body),
  action: (id, verb) => request('POST', `${run(id)}/${verb}`),
  remove: (id) => request('DELETE', run(id)),
  patchParameters: (id, patch) => request('PATCH', `${run(id)}/parameters`, patch),
  timeseries: (id) => request('GET', `${run(id)}/timeseries?max_points=${HISTORY_POINTS}`),
  /** Every file of the run directory: [{path, bytes, modified, url}]. */
  files: (id) => request('GET', `${run(id)}/files`),
  /** The run's reference e_v(t) and -de_v/dt (404 with the reason when it has none). */
  reference: (id) => request('GET', `${run(id)}/reference`),
  /** Every analysis frame's scalars (stats/snapshots.csv), decimated as the time series. */
  analysisHistory: (id) => request('GET', `${run(id)}/analysis?max_points=${HISTORY_POINTS}`),
  spectrum: (id) => request('GET', `${run(id)}/spectrum`),
  statistics: (id) => request('GET', `${run(id)}/statistics`),
  /** The last `lines` lines of the run's run.log, as text. */
  log: (id, lines) => request('GET', `${run(id)}/log?lines=${lines}`, undefined, { text: true }),
  frames: (id) => request('GET', `${run(id)}/frames`),
  frameUrl: (id, file) => `${run(id)}/frames/${encodeURIComponent(file)}`,
  imageUrl: (id, field) => `${run(id)}/images/${encodeURIComponent(field)}`,
};
