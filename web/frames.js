// SPDX-License-Identifier: GPL-3.0-or-later
// The live images (ω², |τ_SFS|) of the selected run and its saved frames, with the scrubber.

import { api } from './api.js';
import { formatNumber } from './charts.js';
import { IMAGE_FIELDS, $, app, setText, showStatus, errorText } from './state.js';

export function onImage(id, header, blob) {
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
  // The 3D view's panel shows once the run has one (render.view3d).
  if (field === 'view3d') $('fig-view3d').hidden = false;
}

export function addFrames(list) {
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

export function renderFrames() {
  const scrubber = $('frame-scrubber');
  const n = app.frames.length;
  scrubber.disabled = n === 0;
  scrubber.max = String(Math.max(0, n - 1));
  if (app.live) scrubber.value = String(Math.max(0, n - 1));
  $('btn-movie').disabled = n === 0;
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
export function showLatestSavedFrames() {
  for (const f of IMAGE_FIELDS) {
    if (app.shownUrl[f]) continue;
    const g = [...app.frames].reverse().find((x) => x.files[f]);
    if (g) showImage(f, api.frameUrl(app.selectedId, g.files[f]), g, 'saved');
  }
}

export function onScrub() {
  app.live = false;
  renderFrames();
  showFrame(Number($('frame-scrubber').value));
}

export function goLive() {
  app.live = true;
  renderFrames();
  for (const f of IMAGE_FIELDS) showLiveImage(f);
}

/** The selected run's saved frames of the chosen field as a video (POST movies), shown under
 *  the images once the server has encoded it. */
export async function makeMovie() {
  const id = app.selectedId;
  const field = $('movie-field').value;
  const button = $('btn-movie');
  button.disabled = true;
  showStatus('movie-status', `Encoding the saved ${field} frames…`);
  try {
    const made = await api.movie(id, { field });
    if (id !== app.selectedId) return;
    const video = $('movie');
    video.src = `${made.url}?t=${Date.now()}`;  // a new encoding of the same file is a new video
    video.hidden = false;
    video.dataset.frames = String(made.frames);
    showStatus('movie-status', `${made.frames} frames, ${made.width}×${made.height} px, ` +
      `${formatNumber(made.duration_seconds)} s (${formatNumber(made.bytes / 1024)} KiB, ${made.path}).`, 'ok');
  } catch (e) {
    if (id === app.selectedId) showStatus('movie-status', `No movie: ${errorText(e)}`, 'error');
  } finally {
    button.disabled = app.frames.length === 0;
  }
}

/** A run selected anew shows no movie of the one before. */
export function clearMovie() {
  const video = $('movie');
  video.removeAttribute('src');
  video.hidden = true;
  showStatus('movie-status', '');
}
