// SPDX-License-Identifier: GPL-3.0-or-later
// The selected run's log (the end of run.log) and its run directory's files as download links.

import { api } from './api.js';
import { $, app, fmtBytes } from './state.js';

const LOG_LINES = 500;     // of run.log shown

/** The end of the selected run's run.log into the log panel, kept scrolled to the bottom when
 *  the reader is there. */
export async function refreshLog() {
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
export async function refreshFiles() {
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
