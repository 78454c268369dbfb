// Mouse, touch and keyboard input mapped onto the OrbitCamera:
//   drag: orbit around the target; right-drag or shift-drag: pan; wheel: zoom;
//   one finger: orbit; two fingers: pinch zoom + pan;
//   WASD / arrow keys: fly (W/S/Up/Down forward/back, A/D/Left/Right strafe), E/Q up/down,
//   Shift flies faster. Up (E/Q, and the axis orbits turn about) is Welcome.up.

const FLY_KEYS = new Set(['KeyW', 'KeyA', 'KeyS', 'KeyD', 'KeyQ', 'KeyE', 'ArrowUp', 'ArrowDown', 'ArrowLeft', 'ArrowRight']);

export class Controls {
  // getCamera(): the current OrbitCamera or null (before the first Welcome).
  // options: keyTarget: what listens for the fly keys (the window for a page that is all view;
  //            the canvas itself where the view is a box among other things, so the keys work
  //            while it has the focus and leave the host page's keys alone);
  //          wheelOverPage: a wheel over the page's bare body zooms too (a page that is all view,
  //            where the re-projected canvas may not cover the window);
  //          focusOnPointer: a touch of the view gives it the focus (keys on the canvas);
  //          signal: an AbortSignal that removes every listener (CatgsViewer.close()).
  constructor(element, getCamera, { keyTarget = window, wheelOverPage = true, focusOnPointer = false, signal } = {}) {
    this.el = element;
    this.getCamera = getCamera;
    this.focusOnPointer = focusOnPointer;
    this.pointers = new Map(); // pointerId -> { x, y, button, shift }
    this.pinch = null; // { dist, mid } of the previous two-finger event
    this.keys = new Set();
    this.shiftHeld = false;

    const on = (target, type, fn, opts = {}) => target.addEventListener(type, fn, { ...opts, signal });
    on(element, 'pointerdown', (e) => this._down(e));
    on(element, 'pointermove', (e) => this._move(e));
    on(element, 'pointerup', (e) => this._up(e));
    on(element, 'pointercancel', (e) => this._up(e));
    on(element, 'wheel', (e) => this._wheel(e), { passive: false });
    // While the canvas is re-projected (a CSS transform until the next frame) it may not cover
    // the window: a wheel over the uncovered page zooms too.
    if (wheelOverPage) {
      on(window, 'wheel', (e) => {
        if (e.target === document.body || e.target === document.documentElement) this._wheel(e);
      }, { passive: false });
    }
    on(element, 'contextmenu', (e) => e.preventDefault()); // right-drag pans
    on(keyTarget, 'keydown', (e) => this._key(e, true));
    on(keyTarget, 'keyup', (e) => this._key(e, false));
    // Keys released while the window (or the view) had no focus never send keyup: forget them.
    on(window, 'blur', () => this.keys.clear());
    if (keyTarget !== window) on(keyTarget, 'blur', () => this.keys.clear());
  }

  _down(e) {
    if (this.focusOnPointer) this.el.focus({ preventScroll: true });
    this.el.setPointerCapture(e.pointerId);
    this.pointers.set(e.pointerId, { x: e.clientX, y: e.clientY, button: e.button, shift: e.shiftKey });
    this.pinch = null;
    e.preventDefault();
  }

  _up(e) {
    this.pointers.delete(e.pointerId);
    this.pinch = null;
  }

  _move(e) {
    const p = this.pointers.get(e.pointerId);
    if (!p) return;
    const cam = this.getCamera();
    const dx = e.clientX - p.x;
    const dy = e.clientY - p.y;
    p.x = e.clientX;
    p.y = e.clientY;
    if (!cam) return;
    if (this.pointers.size >= 2) {
      this._twoFinger(cam);
      return;
    }
    // Movement and height both in CSS pixels: the pan needs only their ratio.
    const heightCss = this.el.clientHeight || 1;
    if (p.button === 2 || p.button === 1 || e.shiftKey || p.shift) cam.pan(dx, dy, heightCss);
    else cam.orbit(dx, dy);
  }

  _twoFinger(cam) {
    const [a, b] = [...this.pointers.values()];
    const dist = Math.hypot(a.x - b.x, a.y - b.y);
    const mid = [(a.x + b.x) / 2, (a.y + b.y) / 2];
    if (this.pinch && dist > 0 && this.pinch.dist > 0) {
      cam.zoom(this.pinch.dist / dist); // fingers apart = closer
      cam.pan(mid[0] - this.pinch.mid[0], mid[1] - this.pinch.mid[1], this.el.clientHeight || 1);
    }
    this.pinch = { dist, mid };
  }

  _wheel(e) {
    e.preventDefault();
    const cam = this.getCamera();
    if (!cam) return;
    // deltaMode 1 = lines, 2 = pages: bring them to roughly pixels.
    const scale = e.deltaMode === 1 ? 16 : e.deltaMode === 2 ? 400 : 1;
    cam.zoom(Math.exp(e.deltaY * scale * 0.001));
  }

  _key(e, down) {
    const t = e.target;
    if (t && (t.tagName === 'INPUT' || t.tagName === 'TEXTAREA' || t.isContentEditable)) return;
    this.shiftHeld = e.shiftKey;
    if (!FLY_KEYS.has(e.code)) return;
    if (down) this.keys.add(e.code);
    else this.keys.delete(e.code);
    e.preventDefault(); // arrows would scroll the page
  }

  // Applies held keys for `dt` seconds; called once per animation frame.
  update(dt) {
    const cam = this.getCamera();
    if (!cam || this.keys.size === 0) return;
    const k = (code) => (this.keys.has(code) ? 1 : 0);
    const forward = k('KeyW') + k('ArrowUp') - k('KeyS') - k('ArrowDown');
    const right = k('KeyD') + k('ArrowRight') - k('KeyA') - k('ArrowLeft');
    const up = k('KeyE') - k('KeyQ');
    // A quarter of the scene scale (Welcome.scene_scale: a typical viewing distance, such as the
    // training cameras' distance from the orbit centre) per second: the subject is reached in
    // about 4 s, or 1 s with Shift.
    const speed = cam.sceneScale * 0.25 * (this.shiftHeld ? 4 : 1);
    cam.fly(Math.min(dt, 0.1), Math.sign(forward), Math.sign(right), Math.sign(up), speed);
  }
}
