// Stats overlay (FPS, pose-to-frame latency, frame size, renderer/encoder) and status messages.

export class Overlay {
  constructor(statsEl, messagesEl) {
    this.statsEl = statsEl;
    this.messagesEl = messagesEl;
    this.messages = new Map(); // id -> { text, level }
    this.info = null;
    this.lastDrawMs = null;
    this.intervalMs = null;
    this.latencyMs = null;
    this.frameSize = null;
    this.rttMs = null;
    this.serverStats = null;
    this.codec = null;
  }

  setSession(welcome, codecName) {
    this.info = {
      scene: welcome.scene_name || '?',
      renderer: welcome.renderer || '?',
      encoder: welcome.encoder || '?',
      pipeline: welcome.pipeline || '',
      codec: codecName,
    };
    this.render();
  }

  clearSession() {
    this.info = null;
    this.lastDrawMs = null;
    this.intervalMs = null;
    this.latencyMs = null;
    this.render();
  }

  frameDrawn(nowMs, latencyMs, width, height, codec) {
    // FPS from a smoothed frame interval: readable at 60 fps and at 0.5 fps alike (a count over
    // the last second reads 0 or 1 for a slow CPU renderer).
    if (this.lastDrawMs !== null) {
      const interval = nowMs - this.lastDrawMs;
      this.intervalMs = this.intervalMs === null ? interval : this.intervalMs * 0.8 + interval * 0.2;
    }
    this.lastDrawMs = nowMs;
    // Smooth so the number can be read while it updates every frame.
    if (Number.isFinite(latencyMs)) {
      this.latencyMs = this.latencyMs === null ? latencyMs : this.latencyMs * 0.8 + latencyMs * 0.2;
    }
    this.frameSize = `${width}x${height}`;
    this.codec = codec;
  }

  setRtt(ms) {
    this.rttMs = ms;
  }

  setServerStats(stats) {
    this.serverStats = stats;
  }

  fps(nowMs) {
    if (this.lastDrawMs === null || this.intervalMs === null || !(this.intervalMs > 0)) return 0;
    // No frame for a while (stream idle: the camera is still): say 0 rather than a stale rate.
    if (nowMs - this.lastDrawMs > Math.max(3000, 3 * this.intervalMs)) return 0;
    return 1000 / this.intervalMs;
  }

  showMessage(id, text, level = 'error') {
    this.messages.set(id, { text, level, shownAt: performance.now() });
    this.renderMessages();
  }

  // minAgeMs keeps a message up at least that long (a server error followed by a quick
  // reconnect must still be readable).
  clearMessage(id, minAgeMs = 0) {
    const m = this.messages.get(id);
    if (!m) return;
    const wait = m.shownAt + minAgeMs - performance.now();
    if (wait > 0) {
      setTimeout(() => {
        if (this.messages.get(id) === m) this.clearMessage(id);
      }, wait);
      return;
    }
    this.messages.delete(id);
    this.renderMessages();
  }

  // Everything the overlay shows, as text (for the test hook and logs).
  text() {
    const msgs = [...this.messages.values()].map((m) => m.text);
    return [this.statsEl.textContent, ...msgs].join('\n');
  }

  render(nowMs = performance.now()) {
    const lines = [];
    lines.push(
      `FPS ${fmtFps(this.fps(nowMs))}  latency ${this.latencyMs === null ? '-' : `${Math.round(this.latencyMs)} ms`}` +
        `  frame ${this.frameSize || '-'}`,
    );
    if (this.info) {
      const pipeline = this.info.pipeline ? ` (${this.info.pipeline})` : '';
      lines.push(`renderer ${this.info.renderer}${pipeline}  encoder ${this.info.encoder}  ${this.codec || this.info.codec}`);
      lines.push(`scene ${this.info.scene}${this.rttMs === null ? '' : `  rtt ${Math.round(this.rttMs)} ms`}`);
    } else {
      lines.push('not connected');
    }
    const s = this.serverStats;
    if (s) {
      lines.push(
        `server: render ${num(s.render_ms_mean)} ms  encode ${num(s.encode_ms_mean)} ms` +
          `  ${num((s.bytes_per_second * 8) / 1e6)} Mbit/s  skipped ${s.poses_skipped || 0}`,
      );
    }
    this.statsEl.textContent = lines.join('\n');
  }

  renderMessages() {
    this.messagesEl.replaceChildren();
    for (const [id, { text, level }] of this.messages) {
      const div = document.createElement('div');
      div.className = `msg ${level}`;
      div.dataset.id = id;
      div.textContent = text;
      this.messagesEl.appendChild(div);
    }
    this.messagesEl.hidden = this.messages.size === 0;
  }
}

const fmtFps = (v) => (v >= 10 || v === 0 ? v.toFixed(0) : v.toFixed(1));
const num = (v) => (Number.isFinite(v) ? v.toFixed(1) : '-');
