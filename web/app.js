// SPDX-License-Identifier: GPL-3.0-or-later
// sphles dashboard: run list, run creation, and for the selected run live images, plots,
// parameter changes and run control. Talks only to the sphles server that served this page
// (REST + one WebSocket per selected run, docs/api.md); no build step at run time.
// This module wires the page at start-up; the views are modules of their own (state.js holds
// what they share).

import { api, getToken, setToken } from './api.js';
import { plottingAvailable } from './charts.js';
import { $, app, showStatus, isActive } from './state.js';
import { toggleCompared } from './plots.js';
import { onCompareSlide } from './compare.js';
import { onScrub, goLive, makeMovie } from './frames.js';
import { onApplyParameters, resetParamForm } from './live_parameters.js';
import { listenToRunList } from './runs.js';
import { refreshLog, refreshFiles } from './run_files.js';
import { onEstimateReference, onComputeReference, onToggleReference } from './references.js';
import { POLL_MS, pollRuns, selectRun, onAction } from './run_view.js';
import {
  loadPresets, cloneSelectedRun, fillCreateForm, onCreate, onEstimate, applyLiveChoice, loadSceneSchema,
} from './create.js';

const LOG_POLL_MS = 3000;  // the selected run's log while it is active

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
  $('btn-movie').addEventListener('click', makeMovie);
  $('compare-slider').addEventListener('input', onCompareSlide);
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
    if (!document.hidden && isActive(app.summary)) refreshLog();
  }, LOG_POLL_MS);
}

main();
