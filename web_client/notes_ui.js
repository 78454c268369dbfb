// The Notes panel (issue 38): hotspots (the server's and the viewer's own), the measurement and
// the scale; markers and the measurement line drawn over the canvas where the camera sees them.
// The maths is annotations.js; the page (app.js) gives the camera, the depth probe and navigation.

import { lookAt } from './viewer/viewer.js';
import {
  decodeNotes, encodeNotes, hotspotId, hotspotTour, measure, normaliseAnnotations, projectPoint, scaleFrom, viewOf,
} from './annotations.js';

const $ = (id) => document.getElementById(id);

export class NotesUi {
  // app: { camera() -> OrbitCamera|null, probe(cssX, cssY) -> Promise<DepthResult>,
  //        notice(text, level, ms), flyTo(pose), playTour(waypoints), save(json) -> bool,
  //        clearNotice(), linkChanged(), closePanel(), openPanel() }
  constructor(app) {
    this.app = app;
    this.server = { version: 1, hotspots: [] }; // the scene's file (Annotations)
    this.serverError = '';
    this.canSave = false;
    this.own = []; // the viewer's own hotspots (the share link)
    this.measurePoints = []; // 0..2 world points
    this.ownScale = null; // metres per unit the viewer set (the share link)
    this.mode = null; // null | 'hotspot' | 'measure'
    this.pending = null; // the point a hotspot being written goes to
    this.reopenPanel = false; // the panel was open when the mode began: it comes back at its end
    this.lastProbe = null;
    this.markers = new Map(); // id -> element
    this._wire();
    this._status();
  }

  // ---- what the page and its test hook read ----

  get hotspots() {
    return [...this.server.hotspots.map((h) => ({ ...h, own: false })), ...this.own.map((h) => ({ ...h, own: true }))];
  }

  get metresPerUnit() {
    return this.ownScale || this.server.metres_per_unit || null;
  }

  get measurement() {
    if (this.measurePoints.length < 2) return null;
    const [a, b] = this.measurePoints;
    return { a, b, ...measure(a, b, this.metresPerUnit) };
  }

  snapshot() {
    return {
      hotspots: this.hotspots,
      measurement: this.measurement,
      measurePoints: this.measurePoints.map((p) => p.slice()),
      metresPerUnit: this.metresPerUnit,
      mode: this.mode,
      canSave: this.canSave,
      serverError: this.serverError,
      lastProbe: this.lastProbe,
    };
  }

  // ---- the server's annotations and the link ----

  // Annotations from the server: after Welcome, and the answer to a save.
  onAnnotations(msg) {
    this.canSave = !!msg.can_save;
    $('btn-save-notes').hidden = !this.canSave;
    if (msg.error) {
      this.serverError = msg.error;
      // A bad file on the server: the scene still shows, and the page says why there are no hotspots.
      this.app.notice(msg.saved === false && this.pendingSave ? `not saved: ${msg.error}` : `hotspots: ${msg.error}`, 'warn', 6000);
    } else {
      this.serverError = '';
    }
    if (msg.json) {
      try {
        this.server = normaliseAnnotations(JSON.parse(msg.json));
      } catch (e) {
        this.serverError = `the server's hotspots: ${e.message}`;
      }
    } else if (!msg.error) {
      this.server = { version: 1, hotspots: [] };
    }
    if (msg.saved) {
      // What the viewer added is in the file now.
      this.own = [];
      this.ownScale = null;
      this.app.notice('hotspots saved on the server');
      this.app.linkChanged();
    }
    this.pendingSave = false;
    this._render();
  }

  // ?notes= of the page's link: the viewer's own hotspots, measurement and scale.
  fromLink(value) {
    if (!value) return;
    try {
      const n = decodeNotes(value);
      this.own = n.hotspots;
      this.measurePoints = n.measure || [];
      this.ownScale = n.metresPerUnit;
    } catch (e) {
      this.app.notice(`the notes in this link were ignored: ${e.message}`, 'warn', 6000);
    }
    this._render();
  }

  linkValue() {
    return encodeNotes({ hotspots: this.own, measure: this.measurePoints.length === 2 ? this.measurePoints : null, metresPerUnit: this.ownScale });
  }

  // ---- actions ----

  setMode(mode) {
    const was = this.mode;
    this.mode = this.mode === mode ? null : mode;
    if (this.mode === 'measure' && this.measurePoints.length === 2) this.measurePoints = [];
    // The whole scene takes the clicks: the panel closes (it would cover much of a small screen),
    // and comes back when the action ends (placed, measured, cancelled, Esc).
    this.app.clearNotice();
    if (this.mode !== 'hotspot' && this.pending) this._closeForm();
    if (this.mode && !was) this.reopenPanel = !$('notes').hidden;
    if (!this.mode && was && this.reopenPanel) {
      this.reopenPanel = false;
      this.app.openPanel();
    }
    if (this.mode) {
      this.app.closePanel();
      this.showCard(null);
      this.app.notice(this.mode === 'hotspot' ? 'click the scene where the hotspot goes (Esc: cancel)'
        : 'click two points to measure between (Esc: cancel)', 'info', 6000);
    }
    $('btn-add-hotspot').setAttribute('aria-pressed', String(this.mode === 'hotspot'));
    $('btn-measure').setAttribute('aria-pressed', String(this.mode === 'measure'));
    document.body.classList.toggle('picking', !!this.mode);
    this._status();
    return this.mode;
  }

  // A click on the scene at CSS pixel (x, y) of the canvas, in the current mode.
  async pick(x, y) {
    const mode = this.mode;
    if (!mode) return null;
    let r;
    try {
      r = await this.app.probe(x, y);
    } catch (e) {
      this.app.notice(`depth: ${e.message}`, 'warn');
      return null;
    }
    this.lastProbe = r;
    if (this.mode !== mode) return r; // cancelled (Esc) while the server looked
    if (r.error) {
      this.app.notice(`depth: ${r.error}`, 'warn', 4000);
      return r;
    }
    if (!r.hit) {
      this.app.notice('no surface there: click on the scene', 'warn');
      return r;
    }
    const p = [r.point.x || 0, r.point.y || 0, r.point.z || 0];
    if (mode === 'measure') {
      if (this.measurePoints.length >= 2) this.measurePoints = [];
      this.measurePoints.push(p);
      if (this.measurePoints.length === 2) {
        this.setMode(null); // done: the next drag orbits again (M measures anew)
        this.app.notice(`distance ${this.measurement.text}`);
        this.app.linkChanged();
      }
    } else if (mode === 'hotspot') {
      this.app.clearNotice();
      this.pending = p;
      $('hotspot-form').hidden = false;
      $('hotspot-title').focus();
    }
    this._render();
    return r;
  }

  // Adds a hotspot at the pending point (the last click in 'hotspot' mode).
  addHotspot(title, text = '', keepView = true) {
    if (!this.pending) throw new Error('click the scene where the hotspot goes first');
    title = String(title).trim();
    if (!title) throw new Error('a hotspot needs a title');
    const taken = new Set(this.hotspots.map((h) => h.id));
    const h = { id: hotspotId(title, taken), title, text: String(text), position: this.pending };
    const cam = this.app.camera();
    if (keepView && cam) {
      const p = cam.pose();
      h.view = { position: p.position, orientation: p.orientation, fov: p.fovDeg };
    }
    this.own.push(h);
    this._closeForm();
    this.setMode(null);
    this.app.linkChanged();
    this._render();
    return h.id;
  }

  // Esc: ends what is under way (the new hotspot's form, adding a hotspot, measuring); false when
  // nothing was.
  escape() {
    if (!this.mode && !this.pending) return false;
    this._closeForm();
    this.setMode(null);
    return true;
  }

  // The new hotspot's form goes, with what was typed into it and the point it was for.
  _closeForm() {
    this.pending = null;
    const form = $('hotspot-form');
    if (form.contains(document.activeElement)) document.activeElement.blur();
    form.hidden = true;
    form.reset();
  }

  _viewFor(h) {
    const cam = this.app.camera();
    return viewOf(h.position, cam.pose(), cam.up, cam.sceneScale * 0.3, lookAt);
  }

  // Flies to a hotspot's view (or a view of its point) and shows its card.
  open(id) {
    const h = this.hotspots.find((x) => x.id === id);
    const cam = this.app.camera();
    if (!h || !cam) return false;
    const to = h.view ? { position: h.view.position, orientation: h.view.orientation, fovDeg: h.view.fov } : this._viewFor(h);
    this.app.flyTo(to);
    this.showCard(h);
    return true;
  }

  showCard(h) {
    const card = $('hotspot-card');
    if (!h) {
      card.hidden = true;
      return;
    }
    card.replaceChildren();
    const title = document.createElement('h3');
    title.textContent = h.title;
    card.append(title);
    if (h.text) card.append(document.createTextNode(h.text));
    card.hidden = false;
    clearTimeout(this.cardTimer);
    this.cardTimer = setTimeout(() => (card.hidden = true), 8000);
  }

  // A tour through the hotspots (the file's tour order, else all of them).
  tour() {
    const doc = { version: 1, hotspots: this.hotspots, tour: this.server.tour };
    const keys = hotspotTour(doc, (h) => this._viewFor(h));
    if (keys.length < 2) {
      this.app.notice('a hotspot tour needs at least 2 hotspots', 'warn');
      return false;
    }
    return this.app.playTour(keys);
  }

  setScale(knownMetres) {
    const m = this.measurement;
    this.ownScale = scaleFrom(m ? m.units : 0, Number(knownMetres));
    this.app.notice(`scale: 1 unit = ${this.ownScale.toPrecision(4)} m`);
    this.app.linkChanged();
    this._render();
    return this.ownScale;
  }

  // Removes a hotspot: the viewer's own at once (the link follows), the server's from what the
  // next Save writes.
  remove(id) {
    const before = this.own.length;
    this.own = this.own.filter((h) => h.id !== id);
    if (this.own.length !== before) {
      this.app.linkChanged();
    } else {
      this.server = { ...this.server, hotspots: this.server.hotspots.filter((h) => h.id !== id) };
      if (this.server.tour) this.server.tour = this.server.tour.filter((t) => t !== id);
      this.app.notice('removed here: Save on server to remove it from the file');
    }
    this._render();
  }

  clearMeasure() {
    this.measurePoints = [];
    this.app.linkChanged();
    this._render();
  }

  // Sends every hotspot (the server's and the viewer's own) and the scale to be saved.
  save() {
    const doc = { version: 1, hotspots: this.hotspots.map(({ own, ...h }) => h) };
    if (this.metresPerUnit) doc.metres_per_unit = this.metresPerUnit;
    if (this.server.tour) doc.tour = this.server.tour;
    const json = JSON.stringify(normaliseAnnotations(doc));
    this.pendingSave = true;
    return this.app.save(json);
  }

  // ---- drawing: every animation frame ----

  update() {
    const cam = this.app.camera();
    const w = window.innerWidth;
    const h = window.innerHeight;
    const pose = cam ? cam.pose() : null;
    for (const hs of this.hotspots) {
      const el = this.markers.get(hs.id);
      if (!el) continue;
      const s = pose ? projectPoint(pose, hs.position, w, h) : null;
      const on = s && s.x >= 0 && s.y >= 0 && s.x <= w && s.y <= h;
      el.hidden = !on;
      if (on) el.style.transform = `translate(${s.x.toFixed(1)}px, ${s.y.toFixed(1)}px) translate(-50%, -50%)`;
    }
    const line = $('measure-line');
    const label = $('measure-label');
    // The points clicked so far, as dots.
    ['measure-a', 'measure-b'].forEach((id, i) => {
      const q = pose && this.measurePoints[i] ? projectPoint(pose, this.measurePoints[i], w, h) : null;
      const dot = $(id);
      dot.style.display = q ? '' : 'none';
      if (q) {
        dot.setAttribute('cx', q.x);
        dot.setAttribute('cy', q.y);
      }
    });
    const m = this.measurement;
    const a = m && pose ? projectPoint(pose, m.a, w, h) : null;
    const b = m && pose ? projectPoint(pose, m.b, w, h) : null;
    if (a && b) {
      line.setAttribute('x1', a.x);
      line.setAttribute('y1', a.y);
      line.setAttribute('x2', b.x);
      line.setAttribute('y2', b.y);
      line.style.display = '';
      label.textContent = m.text;
      label.style.left = `${(a.x + b.x) / 2}px`;
      label.style.top = `${(a.y + b.y) / 2}px`;
      label.hidden = false;
    } else {
      line.style.display = 'none';
      label.hidden = true;
    }
  }

  // ---- DOM ----

  _render() {
    const layer = $('markers');
    const list = $('hotspot-list');
    const all = this.hotspots;
    const ids = new Set(all.map((h) => h.id));
    for (const [id, el] of this.markers) {
      if (!ids.has(id)) {
        el.remove();
        this.markers.delete(id);
      }
    }
    list.replaceChildren();
    for (const h of all) {
      let el = this.markers.get(h.id);
      if (!el) {
        el = document.createElement('button');
        el.type = 'button';
        el.className = 'marker';
        el.style.left = '0';
        el.style.top = '0';
        el.addEventListener('click', () => this.open(el.dataset.id));
        layer.append(el);
        this.markers.set(h.id, el);
      }
      el.dataset.id = h.id;
      el.textContent = h.title;
      el.title = h.text || h.title;
      el.classList.toggle('own', h.own);
      const li = document.createElement('li');
      const name = document.createElement('span');
      name.textContent = `${h.title}${h.own ? ' (yours)' : ''}`;
      name.addEventListener('click', () => this.open(h.id));
      li.append(name);
      // The viewer's own can go; the server's only for an author (gone from the file at Save).
      if (h.own || this.canSave) {
        const del = document.createElement('button');
        del.type = 'button';
        del.className = 'delete';
        del.textContent = '×';
        del.title = h.own ? 'remove' : 'remove (Save on server to keep it so)';
        del.addEventListener('click', () => this.remove(h.id));
        li.append(del);
      }
      list.append(li);
    }
    this._status();
    this.update();
  }

  _status() {
    const n = this.hotspots.length;
    const parts = [n ? `${n} hotspot${n === 1 ? '' : 's'}` : 'no hotspots'];
    const m = this.measurement;
    if (m) parts.push(`distance ${m.text}`);
    if (this.metresPerUnit) parts.push(`1 unit = ${this.metresPerUnit.toPrecision(4)} m`);
    if (this.mode === 'hotspot') parts.push('click the scene where the hotspot goes');
    if (this.mode === 'measure') parts.push(`click point ${this.measurePoints.length + 1} of 2`);
    if (this.serverError) parts.push(`server file: ${this.serverError}`);
    $('notes-status').textContent = parts.join(' · ');
  }

  _wire() {
    $('btn-add-hotspot').addEventListener('click', () => this.setMode('hotspot'));
    $('hotspot-card').addEventListener('click', () => this.showCard(null));
    $('btn-measure').addEventListener('click', () => this.setMode('measure'));
    $('btn-clear-measure').addEventListener('click', () => this.clearMeasure());
    $('btn-hotspot-tour').addEventListener('click', () => this.tour());
    $('btn-save-notes').addEventListener('click', () => this.save());
    $('btn-cancel-hotspot').addEventListener('click', () => this.escape());
    $('hotspot-form').addEventListener('submit', (e) => {
      e.preventDefault();
      try {
        this.addHotspot($('hotspot-title').value, $('hotspot-text').value, $('hotspot-keep-view').checked);
      } catch (err) {
        this.app.notice(err.message, 'warn');
      }
    });
    $('scale-form').addEventListener('submit', (e) => {
      e.preventDefault();
      try {
        this.setScale($('scale-metres').value);
      } catch (err) {
        this.app.notice(err.message, 'warn');
      }
    });
  }
}
