// SPDX-License-Identifier: GPL-3.0-or-later
// The selected run: selecting it (its stream, the history the stream does not repeat), the run
// list polled to keep its summary current, and its controls (start, pause, resume, stop, delete).

import { api, cancelRunRequests, getToken } from './api.js';
import { RunStream } from './stream.js';
import { IMAGE_FIELDS, $, app, setText, showStatus, isCancelled, errorText, isActive } from './state.js';
import { ensureCharts, scheduleRedraw, loadReference } from './plots.js';
import { onImage, addFrames, renderFrames, showLatestSavedFrames, clearMovie } from './frames.js';
import { renderRunList } from './runs.js';
import { refreshLog, refreshFiles } from './run_files.js';
import { applyDetail, mergeSummary, renderHeader } from './run_header.js';
import { applyAvailable, resetReferenceForm } from './references.js';
import { onStreamMessage, addTimeseries, addAnalysisHistory, onSpectrum, onStatistics } from './messages.js';

export const POLL_MS = 2000;

/** The run list, polled: the selected run's summary follows it, a run deleted elsewhere is
 *  deselected, and on opening the page a run is picked. */
export async function pollRuns() {
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
        [...app.runs].reverse().find(isActive) ?? app.runs[app.runs.length - 1];
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

export function selectRun(id) {
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
  clearMovie();
  $('fig-view3d').hidden = true;
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

export async function onAction(event) {
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
