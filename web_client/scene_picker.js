// The scene picker: a server with several scenes lists them at GET /scenes; the picker shows them
// and choosing one reopens the page on it (?scene=NAME; a view in the URL belongs to the old scene
// and goes). ?scene=NAME of a scene the server lacks: the picker moves from the toolbar into the
// state message (in a form: the messages take no pointer otherwise), with every scene there is.

import { withoutView } from './view_link.js';

// A /scenes entry as the picker shows it. A scene not loaded yet whose format cannot be peeked
// has `gaussians: null`: its name alone, rather than a made-up "(0.00 M)".
export function sceneLabel(s) {
  const n = s.gaussians;
  if (typeof n !== 'number' || !Number.isFinite(n)) return String(s.name);
  return `${s.name} (${(n / 1e6).toFixed(2)} M)`;
}

export class ScenePicker {
  // select: the toolbar's <select>; sceneParam: the page's ?scene= ('' for none).
  constructor(select, sceneParam) {
    this.el = select; // (held: it may be out of the page, moving to the message)
    this.sceneParam = sceneParam;
    // Set once the picker holds the server's scenes (two or more, or one when the page asked for
    // a scene the server lacks); until then every Welcome asks.
    this.loaded = false;
    this.asking = false;
    this.minimum = 2; // one scene is no choice, unless the page asked for another
    this.form = null;
    this.current = ''; // the scene the server opened (Welcome)
    select.addEventListener('change', () => this.choose());
  }

  // A session opened on `sceneName`. A page opened while the server was still starting got no
  // scene list: ask again now.
  welcomed(sceneName) {
    this.current = sceneName;
    this.el.value = sceneName;
    if (!this.loaded) this.load();
  }

  // The form for the no-scene message, the picker in it.
  choice() {
    if (!this.form) {
      this.form = document.createElement('form');
      this.form.addEventListener('submit', (e) => e.preventDefault());
      this.form.append(this.el);
      this.minimum = 1;
      if (!this.loaded && !this.asking) this.load();
    }
    return this.form;
  }

  async load() {
    if (this.loaded || this.asking) return;
    this.asking = true;
    try {
      await this._fill();
    } finally {
      this.asking = false;
    }
  }

  async _fill() {
    let scenes = [];
    try {
      const res = await fetch(new URL('scenes', location.href), { cache: 'no-cache' });
      if (res.ok) scenes = await res.json();
    } catch {
      return; // an older server, or none: no picker
    }
    // (minimum is read after the answer: the no-scene message may have come meanwhile.)
    if (!Array.isArray(scenes) || scenes.length < this.minimum) return;
    const picker = this.el;
    picker.replaceChildren();
    const current = this.current || this.sceneParam || String(scenes[0].name);
    const known = scenes.some((s) => String(s.name) === current);
    if (!known) {
      // A scene the server lacks: no blank picker, an invitation to choose.
      const o = new Option('choose a scene…', '', true, true);
      o.disabled = true;
      picker.append(o);
    }
    for (const s of scenes) {
      const o = document.createElement('option');
      o.value = String(s.name);
      o.textContent = sceneLabel(s);
      picker.append(o);
    }
    if (known) picker.value = current;
    picker.hidden = false;
    this.loaded = true;
  }

  choose() {
    if (!this.el.value) return;
    const url = new URL(withoutView(location.href));
    url.searchParams.set('scene', this.el.value);
    location.assign(url.href);
  }
}
