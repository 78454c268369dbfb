// The WebSocket to the server: binary frames, one protobuf message each (subprotocol catgs.v1),
// and automatic reconnection with exponential backoff.

export const SUBPROTOCOL = 'catgs.v1';

// ws(s)://<host>/ws beside the page unless ?ws=<url> overrides it.
export function defaultWebSocketUrl(loc) {
  const params = new URLSearchParams(loc.search);
  if (params.get('ws')) return params.get('ws');
  const scheme = loc.protocol === 'https:' ? 'wss:' : 'ws:';
  return `${scheme}//${loc.host}/ws`;
}

// Backoff before reconnect attempt `attempt` (0-based): 1, 2, 4, 8 s, capped at 10 s.
export function backoffMs(attempt) {
  return Math.min(1000 * 2 ** attempt, 10000);
}

export class Connection {
  // handlers: onOpen(), onMessage(kind, msg), onClose({code, reason, retryInMs}),
  //           onProtocolError(error)
  constructor(url, protocol, handlers) {
    this.url = url;
    this.protocol = protocol;
    this.handlers = handlers;
    this.ws = null;
    this.attempt = 0;
    this.retryTimer = null;
    this.stopped = false;
    this.healthySince = 0;
  }

  get isOpen() {
    return !!this.ws && this.ws.readyState === WebSocket.OPEN;
  }

  connect() {
    if (this.stopped) return;
    clearTimeout(this.retryTimer);
    this.retryTimer = null;
    let ws;
    try {
      ws = new WebSocket(this.url, SUBPROTOCOL);
    } catch (e) {
      // A malformed URL throws synchronously; treat it like a failed attempt.
      this._scheduleRetry(1006, String(e.message || e));
      return;
    }
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    ws.onopen = () => this.handlers.onOpen();
    ws.onmessage = (ev) => {
      if (typeof ev.data === 'string') {
        // The protocol has binary frames only; ignore text rather than drop the session.
        this.handlers.onProtocolError(new Error('unexpected text frame from the server'));
        return;
      }
      let decoded;
      try {
        decoded = this.protocol.decodeServer(new Uint8Array(ev.data));
      } catch (e) {
        this.handlers.onProtocolError(e);
        return;
      }
      if (decoded.kind) this.handlers.onMessage(decoded.kind, decoded.msg);
    };
    ws.onclose = (ev) => {
      if (this.ws !== ws) return;
      this.ws = null;
      this._scheduleRetry(ev.code, ev.reason);
    };
    // An error is always followed by close, which does the work.
    ws.onerror = () => {};
  }

  // A session was established (Welcome). If it then lasts a while, the next drop starts the
  // backoff from the beginning; a server that accepts and at once drops us still backs off.
  markHealthy() {
    this.healthySince = Date.now();
  }

  _scheduleRetry(code, reason) {
    if (this.stopped) return;
    if (this.healthySince && Date.now() - this.healthySince > 5000) this.attempt = 0;
    this.healthySince = 0;
    const retryInMs = backoffMs(this.attempt++);
    this.retryTimer = setTimeout(() => this.connect(), retryInMs);
    this.handlers.onClose({ code, reason, retryInMs });
  }

  // Sends encoded bytes; false when not connected (the caller will resend state on reconnect).
  send(bytes) {
    if (!this.isOpen) return false;
    this.ws.send(bytes);
    return true;
  }

  get bufferedAmount() {
    return this.ws ? this.ws.bufferedAmount : 0;
  }

  close() {
    this.stopped = true;
    clearTimeout(this.retryTimer);
    if (this.ws) this.ws.close(1000, 'client closing');
  }
}
