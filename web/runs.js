// SPDX-License-Identifier: GPL-3.0-or-later
// The run list: one item per run with its state, progress and compare box. What a click selects
// and what a compare box overlays are the start-up's to say (listenToRunList), so that the list
// knows nothing of the views above it.

import { api } from './api.js';
import { formatNumber } from './charts.js';
import { $, app } from './state.js';
import { mergeSummary } from './run_header.js';

/** Calls `select(id)` when a run's item is clicked and `compare(id, on)` when its compare box is
 *  ticked or cleared: one listener each on the list, whose items renderRunList keeps or adds. */
export function listenToRunList(select, compare) {
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

export function renderRunList() {
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

let pollSoonTimer = null;
export function pollSoon() {
  // A state change also changes the run list, and the selected run's actions; refresh them
  // without waiting for the next poll.
  if (pollSoonTimer) return;
  pollSoonTimer = setTimeout(async () => {
    pollSoonTimer = null;
    try {
      app.runs = await api.runs();
      renderRunList();
      const selected = app.runs.find((r) => r.id === app.selectedId);
      if (selected) mergeSummary(selected);
    } catch {
      // the regular poll reports the connection state
    }
  }, 100);
}
