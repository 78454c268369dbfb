// What the page says: the developer stats (?stats=1), the connection state in plain words (with
// its action buttons or the token field), and short notices (decoder trouble, "link copied").
// Nothing shown is older than what it describes: a dropped session clears the stats, an idle
// server interval says idle instead of "render 0.0 ms".

export class Overlay {
  // els: { stats, messages } elements; showStats: the developer stats are visible (?stats=1);
  // noticeEl: where the short notices (message id 'notice') go instead of the centred messages,
  // a line at the bottom of the page, clear of the middle where the measured distance and the
  // scene's subject usually are.
  constructor(statsEl, messagesEl, { showStats = false, noticeEl = null } = {}) {
    this.statsEl = statsEl;
    this.messagesEl = messagesEl;
    this.noticeEl = noticeEl;
    this.showStats = showStats;
    this.statsEl.hidden = !showStats;
    this.messages = new Map(); // id -> { text, level, actions }
    this._resetMeasurements();
  }

  // Everything measured on a session (nothing of it may outlive the session).
  _resetMeasurements() {
    this.info = null;
    this.lastDrawMs = null;
    this.intervalMs = null;
    this.latencyMs = null;
    this.frameSize = null;
    this.rttMs = null;
    this.serverStats = null;
    this.serverIdle = false;
    this.prevFramesSent = null;
    this.codec = null;
  }

  setSession(welcome) {
    this.info = {
      scene: welcome.scene_name || '?',
      renderer: welcome.renderer || '?',
      encoder: welcome.encoder || '?',
      pipeline: welcome.pipeline || '',
    };
    this.render();
  }

  // The session ended: nothing measured on it stays on screen.
  clearSession() {
    this._resetMeasurements();
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

  // Stats cover the last interval (about a second); with no frame in it the means are 0, which
  // is "nothing rendered", not "rendered in 0 ms".
  setServerStats(stats) {
    const sent = stats.frames_sent || 0;
    this.serverIdle = this.prevFramesSent !== null && sent === this.prevFramesSent;
    this.prevFramesSent = sent;
    this.serverStats = stats;
  }

  // The stream is idle when no frame came for a while (the camera is still): no rate to show.
  idle(nowMs) {
    return this.lastDrawMs === null || nowMs - this.lastDrawMs > Math.max(3000, 3 * (this.intervalMs || 0));
  }

  fps(nowMs) {
    if (this.idle(nowMs) || this.intervalMs === null || !(this.intervalMs > 0)) return null;
    return 1000 / this.intervalMs;
  }

  // level: 'error' | 'warn' | 'info'; actions: [{ label, onClick }] buttons, or an element to
  // append (the token form).
  showMessage(id, text, level = 'error', actions = []) {
    const prev = this.messages.get(id);
    // Re-rendering the same text every tick would steal focus from the token field.
    if (prev && prev.text === text && prev.level === level && prev.actions === actions) return;
    this.messages.set(id, { text, level, actions });
    this.renderMessages();
  }

  clearMessage(id) {
    if (!this.messages.delete(id)) return;
    this.renderMessages();
  }

  // Everything the overlay shows, as text (for the test hook and logs).
  text() {
    const msgs = [...this.messages.values()].map((m) => m.text);
    return [this.showStats ? this.statsEl.textContent : '', ...msgs].filter(Boolean).join('\n');
  }

  render(nowMs = performance.now()) {
    if (!this.showStats) return;
    const lines = [];
    if (!this.info) {
      lines.push('not connected');
    } else {
      const fps = this.fps(nowMs);
      const idle = fps === null;
      lines.push(
        `FPS ${idle ? 'idle' : fmtFps(fps)}  latency ${this.latencyMs === null ? '-' : `${Math.round(this.latencyMs)} ms`}`,
      );
      lines.push(`frame ${this.frameSize || '-'}  ${this.codec || 'H.264'}`);
      const pipeline = this.info.pipeline ? ` (${this.info.pipeline})` : '';
      lines.push(`renderer ${this.info.renderer}${pipeline}  encoder ${this.info.encoder}`);
      // The page's own round trip (Ping -> Pong, through the server's queue), apart from the
      // TCP connection's below.
      lines.push(`scene ${this.info.scene}${this.rttMs === null ? '' : `  ping ${Math.round(this.rttMs)} ms`}`);
      const s = this.serverStats;
      if (s && this.serverIdle) {
        lines.push('server: idle (no frame in the last second)');
      } else if (s) {
        lines.push(`server: render ${num(s.render_ms_mean)} ms  encode ${num(s.encode_ms_mean)} ms`);
        // The encoder's picture (the coded frame against the rendered one) and the preset it
        // came from: a host that fills steps the preset down, and this line shows it.
        if (s.encode_psnr_db_mean) lines.push(`  picture ${num(s.encode_psnr_db_mean)} dB (${s.encoder})`);
        // Level of detail: the cut's bound and the Gaussians a frame drew (a scene served with LOD).
        if (s.lod_error_px_mean) {
          lines.push(`  LOD ${num(s.lod_error_px_mean)} px  ${((s.splats_mean || 0) / 1e6).toFixed(2)} M splats`);
        }
        lines.push(`  ${num((s.bytes_per_second * 8) / 1e6)} Mbit/s  skipped ${s.poses_skipped || 0}`);
        // The link's rate controller: what the link carried (only when the server measured it
        // on a full link: Stats.link_kbps 0 otherwise), its round trip, the cap it sets.
        const cap = s.bitrate_cap_kbps ? `cap ${s.bitrate_cap_kbps} kbit/s` : 'not limited';
        const level = s.quality_level ? `  size level ${s.quality_level}` : '';
        const link = s.link_kbps ? `link ${linkRate(s.link_kbps)}  ` : '';
        lines.push(`  ${link}TCP rtt ${num(s.rtt_ms || 0)} ms  ${cap}${level}`);
      }
    }
    this.statsEl.textContent = lines.join('\n');
  }

  renderMessages() {
    this.messagesEl.replaceChildren();
    if (this.noticeEl) this.noticeEl.replaceChildren();
    for (const [id, { text, level, actions }] of this.messages) {
      const div = document.createElement('div');
      div.className = `msg ${level}`;
      div.dataset.id = id;
      const span = document.createElement('span');
      span.textContent = text;
      div.appendChild(span);
      if (actions instanceof Node) {
        div.appendChild(actions);
      } else {
        for (const a of actions) {
          const b = document.createElement('button');
          b.type = 'button';
          b.textContent = a.label;
          b.dataset.action = a.id || a.label;
          b.addEventListener('click', a.onClick);
          div.appendChild(b);
        }
      }
      (id === 'notice' && this.noticeEl ? this.noticeEl : this.messagesEl).appendChild(div);
    }
    this.messagesEl.hidden = this.messagesEl.childElementCount === 0;
    if (this.noticeEl) this.noticeEl.hidden = this.noticeEl.childElementCount === 0;
  }
}

const fmtFps = (v) => (v >= 10 ? v.toFixed(0) : v.toFixed(1));
const num = (v) => (Number.isFinite(v) ? v.toFixed(1) : '-');
// A link rate for the stats: kbit/s below 10 Mbit/s, Mbit/s above.
const linkRate = (kbps) => (kbps < 10000 ? `${Math.round(kbps)} kbit/s` : `${(kbps / 1000).toFixed(0)} Mbit/s`);
