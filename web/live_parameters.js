// SPDX-License-Identifier: GPL-3.0-or-later
// The selected run's live parameters: the form of what a running run may change (PATCH).

import { api } from './api.js';
import { $, app, showStatus, errorText, getPath, setPath, readInput } from './state.js';

export function fillParamForm(scene) {
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

export async function onApplyParameters(event) {
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

export function resetParamForm() {
  for (const input of $('param-form').querySelectorAll('[data-path]')) input.value = input.dataset.initial ?? '';
  showStatus('param-status', '');
}
