// The WebSocket to the server: binary frames, one protobuf message each (subprotocol catgs.v1),
// and automatic reconnection: exponential backoff, or the server's Error.retry_after_ms hint;
// no retry at all after a permanent error (a wrong token, or a Hello refused as invalid such as an
// unknown scene, cannot get better by waiting).

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

// After the server said it is stopping (ERROR_SHUTTING_DOWN), the attempts that find it gone are
// not a network fault: they say "stopping" still and come this often, so the page streams again
// within about a second of the server's return (a restart takes seconds, not the backoff's 8).
// Up to STOPPING_RETRIES of them (two minutes), then the usual backoff.
export const STOPPING_RETRY_MS = 1000;
export const STOPPING_RETRIES = 120;

// ErrorCode values (proto/catgs_stream.proto) the reconnect logic cares about.
export const ERROR_PROTOCOL = 2;
export const ERROR_INVALID_ARGUMENT = 3;
export const ERROR_UNAUTHORIZED = 4;
export const ERROR_SERVER_FULL = 5;
export const ERROR_SHUTTING_DOWN = 7;
export const ERROR_RATE_LIMITED = 9;

// What to do after the server ended a session with `error` ({code, retry_after_ms}; null when
// the connection just dropped). `welcomed`: this connection had a session.
//   { permanent: true }           stop: the same Hello would be refused again
//   { delayMs }                   reconnect after the server's hint
//   { delayMs: null }             reconnect with the usual backoff
export function retryPolicy(error, welcomed) {
  if (!error) return { permanent: false, delayMs: null };
  if (error.code === ERROR_UNAUTHORIZED) return { permanent: true };
  // A refused Hello (unknown protocol version; a scene the server does not have, codecs it does
  // not stream) is refused again: a page and server that do not match need a reload or another
  // scene, not a loop.
  if ((error.code === ERROR_PROTOCOL || error.code === ERROR_INVALID_ARGUMENT) && !welcomed) return { permanent: true };
  const hint = Number(error.retry_after_ms) || 0;
  // RATE_LIMITED's hint is when the server takes the next Hello from this address.
  const hinted = [ERROR_SERVER_FULL, ERROR_SHUTTING_DOWN, ERROR_RATE_LIMITED];
  if (hint > 0 && hinted.includes(error.code)) {
    // Bounded so a bad hint neither floods the server nor parks the page for an hour.
    return { permanent: false, delayMs: Math.min(Math.max(hint, 250), 60000) };
  }
  return { permanent: false, delayMs: null };
}

export class Connection {
  // handlers: onOpen(), onMessage(kind, msg),
  //           onClose({code, reason, retryInMs, error, permanent, reached}),
  //           onProtocolError(error)
  // `reached`: some WebSocket to this server ever opened (else the server was never reachable).
  constructor(url, protocol, handlers) {
    this.url = url;
    this.protocol = protocol;
    this.handlers = handlers;
    this.ws = null;
    this.attempt = 0;
    this.retryTimer = null;
    this.stopped = false;
    this.healthySince = 0;
    this.reached = false;
    this.lastError = null; // the server's Error on the current connection
    this.welcomed = false;
    this.opened = false; // the current attempt's socket opened
    this.stoppingRetries = -1; // >= 0: the server said it is stopping; attempts since (a new session resets)
  }

  get isOpen() {
    return !!this.ws && this.ws.readyState === WebSocket.OPEN;
  }

  connect() {
    clearTimeout(this.retryTimer);
    this.retryTimer = null;
    if (this.stopped) return;
    let ws;
    this.lastError = null;
    this.welcomed = false;
    this.opened = false;
    try {
      ws = new WebSocket(this.url, SUBPROTOCOL);
    } catch (e) {
      // A malformed URL throws synchronously; treat it like a failed attempt.
      this._scheduleRetry(1006, String(e.message || e));
      return;
    }
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    ws.onopen = () => {
      this.reached = true;
      this.opened = true;
      this.handlers.onOpen();
    };
    ws.onmessage = (ev) => {
      if (this.ws !== ws) return;
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
      if (decoded.kind === 'error') this.lastError = decoded.msg;
      if (decoded.kind === 'welcome') this.welcomed = true;
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
    const error = this.lastError;
    const policy = retryPolicy(error, this.welcomed);
    // The server said it is stopping; an attempt that finds no server (its socket never opened)
    // is the same stop, not a new fault. A socket that opens ends it.
    if (error && error.code === ERROR_SHUTTING_DOWN) this.stoppingRetries = 0;
    else if (this.opened) this.stoppingRetries = -1;
    const stopping = this.stoppingRetries >= 0 && this.stoppingRetries < STOPPING_RETRIES;
    const base = { code, reason, error, reached: this.reached, stopping };
    if (policy.permanent) {
      this.stopped = true;
      this.handlers.onClose({ ...base, retryInMs: null, permanent: true });
      return;
    }
    let retryInMs;
    if (stopping && !error) {
      retryInMs = STOPPING_RETRY_MS; // the backoff's count does not move meanwhile
      this.stoppingRetries++;
    } else {
      retryInMs = policy.delayMs ?? backoffMs(this.attempt++);
    }
    this.retryTimer = setTimeout(() => this.connect(), retryInMs);
    this.handlers.onClose({ ...base, retryInMs, permanent: false });
  }

  // Skips the wait before the next attempt ("retry now").
  retryNow() {
    if (this.ws) return;
    this.connect();
  }

  // Starts again after a permanent error (e.g. with a new token), backoff from the start.
  restart() {
    this.stopped = false;
    this.attempt = 0;
    if (this.ws) {
      const ws = this.ws;
      this.ws = null;
      ws.close(1000, 'client restarting');
    }
    this.connect();
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
