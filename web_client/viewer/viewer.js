// The embeddable viewer (issue 63): import this module, from this server or another site's page,
// and use either the CatgsViewer class (catgs_viewer.js) or the <catgs-viewer> element it
// defines, which fills the box the page gives it. README.md "Embedding" documents both.
//
//   <catgs-viewer server="wss://stream.example/ws" scene="garden"></catgs-viewer>
//   <script type="module" src="https://stream.example/viewer.js"></script>

import { CatgsViewer, VIEWER_EVENTS } from './catgs_viewer.js';
import { statusText } from './status_text.js';
import { vrSupported } from './xr.js';

// The library's API is what this module exports (README.md "Embedding", "The module's exports";
// a test holds the two equal and fails on a page that imports another module of the library).
export { CatgsViewer, VIEWER_EVENTS, vrSupported };
export { ERROR_WORDS, statusText } from './status_text.js';
export { defaultWebSocketUrl } from './connection.js';
export { parseMaxSize } from './viewport.js';
export {
  LOADGEN_SECONDS_PER_VIEW, PathRecorder, TOUR_SECONDS_PER_VIEW, fromInriaCameras, fromTraceFile, poseAtTime, resample,
  toInriaCameras, toTraceFile, tourDuration, tourPoseAt,
} from './paths.js';
export {
  cameraForward, cameraRight, intrinsicsFor, lookAt, qnorm, qrotate, vadd, vcross, vdot, vlen, vnorm, vscale, vsub,
} from './camera.js';

// The element's own look: a black box of the page's size (360 px tall unless the page says), the
// view filling it; what the re-projection moves past the box is cut off there.
const STYLE = `
:host { display: block; position: relative; overflow: hidden; isolation: isolate; background: #000; height: 360px; }
:host([hidden]) { display: none; }
canvas.view { display: block; position: relative; width: 100%; height: 100%; touch-action: none; outline: none;
  cursor: grab; transform-origin: 0 0; }
canvas.view:active { cursor: grabbing; }
canvas.backdrop { position: absolute; inset: 0; width: 100%; height: 100%; pointer-events: none; }
canvas.backdrop[hidden] { display: none; }
.message { position: absolute; left: 0; right: 0; top: 50%; transform: translateY(-50%); margin: 0 12px; padding: 8px 12px;
  text-align: center; font: 14px/1.4 system-ui, sans-serif; color: #eee; background: rgba(0, 0, 0, 0.72);
  border-radius: 4px; pointer-events: none; }
.message[hidden] { display: none; }
.message.warn { color: #ffd27a; }
.message.error { color: #ff9a8a; }
.vr { position: absolute; right: 8px; bottom: 8px; font: 13px/1 system-ui, sans-serif; color: #fff; background: rgba(0, 0, 0, 0.6);
  border: 1px solid #aaa; border-radius: 4px; padding: 6px 10px; cursor: pointer; }
`;

// Attributes the viewer is made with; a change makes a new one (the token: a new connection).
const OPTIONS = ['server', 'scene', 'token', 'codec', 'controls'];

// Outside a browser (node, the unit tests that import the page's modules) there is no DOM: the
// element's class then has a plain base and is never defined.
const ElementBase = globalThis.HTMLElement ?? class {};

export class CatgsViewerElement extends ElementBase {
  static get observedAttributes() {
    return OPTIONS;
  }

  constructor() {
    super();
    const root = this.attachShadow({ mode: 'open' });
    const style = document.createElement('style');
    style.textContent = STYLE;
    this.backdrop = document.createElement('canvas');
    this.backdrop.className = 'backdrop';
    this.backdrop.hidden = true;
    this.canvas = document.createElement('canvas');
    this.canvas.className = 'view';
    this.canvas.tabIndex = 0;
    this.canvas.setAttribute('aria-label', 'Streamed 3D Gaussian Splatting view');
    // What the view says while it cannot stream (status_text.js; a host page replaces it with
    // `messages`), over the view: role status, so a screen reader reads it too.
    this.message = document.createElement('div');
    this.message.className = 'message';
    this.message.setAttribute('part', 'message');
    this.message.setAttribute('role', 'status');
    this.message.hidden = true;
    root.append(style, this.backdrop, this.canvas, this.message);
    this.vrButton = null; // "Enter VR", made only where the browser offers immersive VR (_offerVr)
    this.vrAsked = false;
    this.askVr = null;
    this.viewer = null;
    this.messages = null;
    this.messageTimer = null;
  }

  connectedCallback() {
    if (!this.viewer) this._open();
  }

  // Off the page: the session ends (the server's slot is freed); back on it, a new one starts.
  disconnectedCallback() {
    this._close();
  }

  attributeChangedCallback(name, before, value) {
    if (!this.viewer || before === value) return;
    if (name === 'token') {
      this.viewer.setToken(value || '');
      return;
    }
    this._close();
    this._open();
  }

  _open() {
    const attr = (n) => this.getAttribute(n) || '';
    this.viewer = new CatgsViewer({
      canvas: this.canvas,
      backdrop: this.backdrop,
      server: attr('server') || undefined,
      scene: attr('scene'),
      token: attr('token'),
      codec: attr('codec'),
      controls: !/^(off|false|none)$/i.test(attr('controls')),
      keyTarget: this.canvas, // keys fly the camera while the view has the focus only
    });
    // The viewer's events, again on the element (its listeners outlive a new viewer).
    for (const type of VIEWER_EVENTS) {
      this.viewer.addEventListener(type, (e) => this.dispatchEvent(new CustomEvent(type, { detail: e.detail })));
    }
    for (const type of ['status', 'disconnected', 'error']) this.viewer.addEventListener(type, () => this._showStatus());
    this.viewer.addEventListener('vr', (e) => this.vrButton && (this.vrButton.textContent = e.detail.active ? 'Exit VR' : 'Enter VR'));
    this._askVrOnce();
    // The countdowns ("retrying in 3 s") tick while it is not streaming.
    this.messageTimer = setInterval(() => this._showStatus(), 500);
    this.viewer.start().then(() => this._showStatus());
    this._showStatus();
  }

  _close() {
    if (this.viewer) this.viewer.close();
    this.viewer = null;
    clearInterval(this.messageTimer);
    this.messageTimer = null;
  }

  // The status in words in the element's box (hidden while it streams). `messages`, where the
  // host page set it, replaces the words: an object of texts by status ({ 'server-full': 'Busy,
  // back soon' }) or a function (status, words) returning the text ('' hides it).
  _showStatus() {
    const v = this.viewer;
    if (!v) return;
    const words = statusText(v, this.getAttribute('scene') || '');
    if (words === undefined) return;
    let text = words ? words.text : '';
    const own = this.messages;
    if (words && typeof own === 'function') text = own(v.status, text) ?? text;
    else if (words && own && typeof own[v.status] === 'string') text = own[v.status];
    const className = `message ${words ? words.level : ''}`;
    if (this.message.textContent === text && this.message.className === className) return;  // the timer's ticks
    this.message.textContent = text;
    this.message.className = className;
    this.message.hidden = !text;
  }

  // The text the box shows now ('' when none).
  get messageText() {
    return this.message.hidden ? '' : this.message.textContent;
  }

  // Whether a headset can show the stream is asked once the visitor points at, touches or focuses
  // the view, not at load: asked at load, the question moved the timing of a race in the embed's
  // loader (its first failure before the host page's listener; loader.js now waits for the parse)
  // enough to fail the embed test (README.md "VR"). A view nobody points at needs no button.
  _askVrOnce() {
    if (this.vrAsked) return;
    const events = ['pointerenter', 'focusin', 'touchstart'];
    // One handler for the element's life: a new viewer (an attribute changed) adds it again, once.
    this.askVr = this.askVr || (() => {
      this.vrAsked = true;
      for (const t of events) this.removeEventListener(t, this.askVr);
      vrSupported().then((yes) => yes && this._offerVr());
    });
    for (const t of events) this.addEventListener(t, this.askVr, { passive: true });
  }

  // "Enter VR" at the bottom right of the box (part vr-button), only where a headset can show the
  // stream (xr.js vrSupported): elsewhere the element brings no button of its own.
  _offerVr() {
    if (this.vrButton) return;
    const b = document.createElement('button');
    b.type = 'button';
    b.className = 'vr';
    b.setAttribute('part', 'vr-button');
    b.textContent = this.viewer && this.viewer.vr ? 'Exit VR' : 'Enter VR';
    b.addEventListener('click', () => this._toggleVr());
    this.shadowRoot.append(b);
    this.vrButton = b;
  }

  // The button: into VR, or out of it.
  _toggleVr() {
    const v = this.viewer;
    if (!v) return;
    if (v.vr) v.exitVr();
    else v.enterVr().catch((e) => this.dispatchEvent(new CustomEvent('error', { detail: { name: 'VR', code: 0, reason: e.message, permanent: false, status: v.status } })));
  }

  // ---- the viewer's API on the element ----

  enterVr(options) {
    return this._live().enterVr(options);
  }

  exitVr() {
    return this.viewer ? this.viewer.exitVr() : Promise.resolve(null);
  }

  setPose(spec) {
    return this._live().setPose(spec);
  }

  playPath(path, options) {
    return this._live().playPath(path, options);
  }

  stopPath() {
    if (this.viewer) this.viewer.stopPath();
  }

  resetView() {
    return this.viewer ? this.viewer.resetView() : false;
  }

  pose() {
    return this.viewer ? this.viewer.pose() : null;
  }

  snapshot() {
    return this.canvas.toDataURL('image/png');
  }

  get status() {
    return this.viewer ? this.viewer.status : 'closed';
  }

  get connected() {
    return !!this.viewer && this.viewer.connected;
  }

  get welcome() {
    return this.viewer ? this.viewer.welcome : null;
  }

  get framesDecoded() {
    return this.viewer ? this.viewer.framesDecoded : 0;
  }

  get playing() {
    return this.viewer ? this.viewer.playing : null;
  }

  _live() {
    if (!this.viewer) throw new Error('the viewer is not on the page');
    return this.viewer;
  }
}

if (globalThis.customElements && !customElements.get('catgs-viewer')) customElements.define('catgs-viewer', CatgsViewerElement);
