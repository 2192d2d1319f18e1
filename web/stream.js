// SPDX-License-Identifier: GPL-3.0-or-later
// The WebSocket stream of one run (/api/runs/{id}/stream, docs/api.md), reconnecting with
// exponential backoff until closed by the page. Text messages are JSON; binary messages are
// images: 4-byte big-endian header length L, L bytes of JSON header, then the PNG bytes.

const BACKOFF_FIRST_MS = 500;
const BACKOFF_MAX_MS = 10000;

/**
 * handlers: {
 *   onState({state: 'connecting'|'open'|'closed'|'reconnecting', attempt, delayMs, detail}),
 *   onMessage(json), onImage(header, pngBlob), onOpen()
 * }
 */
export class RunStream {
  constructor(runId, token, handlers) {
    this.runId = runId;
    this.token = token;
    this.handlers = handlers;
    this.socket = null;
    this.timer = null;
    this.attempt = 0;
    this.closed = false;
    this.connect();
  }

  url() {
    const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
    let url = `${scheme}://${location.host}/api/runs/${encodeURIComponent(this.runId)}/stream`;
    if (this.token) url += `?token=${encodeURIComponent(this.token)}`;
    return url;
  }

  connect() {
    this.timer = null;
    if (this.closed) return;
    this.handlers.onState({ state: 'connecting', attempt: this.attempt });
    const socket = new WebSocket(this.url());
    socket.binaryType = 'arraybuffer';
    this.socket = socket;
    socket.onopen = () => {
      if (socket !== this.socket) return;
      this.attempt = 0;
      this.handlers.onState({ state: 'open' });
      this.handlers.onOpen?.();
    };
    socket.onmessage = (event) => {
      if (socket !== this.socket) return;
      if (typeof event.data === 'string') {
        let message;
        try {
          message = JSON.parse(event.data);
        } catch {
          this.handlers.onState({ state: 'open', detail: 'ignored a malformed text message' });
          return;
        }
        this.handlers.onMessage(message);
      } else {
        const image = decodeImage(event.data);
        if (image) this.handlers.onImage(image.header, image.blob);
      }
    };
    socket.onclose = (event) => {
      if (socket !== this.socket) return;
      this.socket = null;
      if (this.closed) {
        this.handlers.onState({ state: 'closed' });
        return;
      }
      const delayMs = Math.min(BACKOFF_MAX_MS, BACKOFF_FIRST_MS * 2 ** this.attempt);
      this.attempt += 1;
      const detail = event.reason || (event.code !== 1000 ? `code ${event.code}` : '');
      this.handlers.onState({ state: 'reconnecting', attempt: this.attempt, delayMs, detail });
      this.timer = setTimeout(() => this.connect(), delayMs);
    };
    // onerror is always followed by onclose, which schedules the reconnection.
    socket.onerror = () => {};
  }

  /** Sends a JSON message; false if the socket is not open. */
  send(message) {
    if (!this.socket || this.socket.readyState !== WebSocket.OPEN) return false;
    this.socket.send(JSON.stringify(message));
    return true;
  }

  /** Reconnects at once (e.g. after the token changed). */
  reconnectNow(token) {
    this.token = token;
    if (this.timer) clearTimeout(this.timer);
    const old = this.socket;
    this.socket = null;
    if (old) old.close(1000, 'reconnecting');
    this.attempt = 0;
    this.connect();
  }

  close() {
    this.closed = true;
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
    const socket = this.socket;
    this.socket = null;
    if (socket) socket.close(1000, 'dashboard closed the stream');
    this.handlers.onState({ state: 'closed' });
  }
}

/** Splits a binary image message into its JSON header and a PNG Blob; null if malformed. */
export function decodeImage(buffer) {
  if (!(buffer instanceof ArrayBuffer) || buffer.byteLength < 4) return null;
  const length = new DataView(buffer).getUint32(0, false);
  if (4 + length > buffer.byteLength) return null;
  let header;
  try {
    header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, length)));
  } catch {
    return null;
  }
  const blob = new Blob([new Uint8Array(buffer, 4 + length)], { type: 'image/png' });
  return { header, blob };
}
