// VR tours (issue 94): an immersive-vr WebXR session on a CatgsViewer. Each XR frame the
// headset's two views become two EyeViews in the scene (stereo.js: the headset anchored to the
// page's camera at entering) and one Pose carrying both goes to the server, which answers with one
// frame holding both eyes side by side (Frame.eye_width). Every display frame, whatever has
// arrived, each eye's half of the newest frame is drawn re-projected to where that eye looks now
// (xr_gl.js: the homography of a plane, reproject.js, from the eye the frame shows to the eye's
// current view), so a head turn never waits on the network. The thumbstick moves the visitor along
// the head's level forward (the page may check each step: the viewer's `driveVr` hook, walk mode's
// rules in app.js).
//
// A mono frame (a server without stereo ignores the eyes; or a headset with one view) is the head's
// pose at the stream's size: both eyes re-project it.
//
// The viewer owns the connection: poses go out through it (its sequence numbers, receipts and
// backpressure), frames come in through it (catgs_viewer.js _drawFrame hands them here while VR
// is on), and it goes back to the flat page when the session ends (_vrEnded).

import { cameraForward, cameraRight, intrinsicsFor, vadd, vdot, vlen, vnorm, vscale, vsub } from './camera.js';
import { depthAt } from './depth_warp.js';
import { invert3, planeDepthFor, reprojectionK } from './reproject.js';
import {
  eyeIntrinsics, eyeViewOf, moveAnchor, verticalFovDeg, vrStreamSize, worldPose, xrAnchor, xrPoseOf,
} from './stereo.js';
import { EyeDrawer } from './xr_gl.js';

// Whether this browser offers immersive VR (a headset, or an emulator such as IWER). Never throws.
export async function vrSupported(xr = globalThis.navigator ? globalThis.navigator.xr : undefined) {
  try {
    return !!xr && (await xr.isSessionSupported('immersive-vr'));
  } catch (_) {
    return false;
  }
}

const STICK_DEAD_ZONE = 0.15;
const WALK_METRES_PER_SECOND = 1.4; // a thumbstick held fully forward, where the scene has a scale
const MAX_STEP_S = 0.1; // a hitch in the display's frames does not become a jump
// Pose.display_hz's range (proto/message_validation.h): outside it the server is told nothing.
const MIN_DISPLAY_HZ = 24;
const MAX_DISPLAY_HZ = 240;

// The thumbstick with the larger deflection (xr-standard gamepads: axes 2 and 3; the left hand's
// first where both are held), as [right, forward] in -1..1, or null inside the dead zone.
function thumbstick(session) {
  let best = null;
  for (const source of session.inputSources || []) {
    const g = source.gamepad;
    if (!g || g.axes.length < 4) continue;
    const v = [g.axes[2], -g.axes[3]];
    const m = Math.hypot(v[0], v[1]);
    if (m > STICK_DEAD_ZONE && (!best || m > best.m || (source.handedness === 'left' && m >= best.m))) best = { v, m };
  }
  return best ? best.v : null;
}

const level = (v, up) => {
  const h = vsub(v, vscale(up, vdot(v, up)));
  return vlen(h) > 1e-6 ? vnorm(h) : [0, 0, 0];
};

export class VrSession {
  // viewer: the CatgsViewer (connected). options: unitsPerMetre (world units in a metre; 1: the
  // scene's unit taken as a metre), planeDepth (world units: where the re-projection's plane lies
  // when a frame carries no depth; default the page's re-projection depth at entering).
  constructor(viewer, { unitsPerMetre = null, planeDepth = null } = {}) {
    this.viewer = viewer;
    this.scaleKnown = unitsPerMetre > 0 && Number.isFinite(unitsPerMetre);
    this.unitsPerMetre = this.scaleKnown ? unitsPerMetre : 1;
    const cam = viewer.camera;
    this.up = cam.up.slice();
    this.planeDepth = planeDepth > 0 ? planeDepth
      : (viewer.reprojectDepth && viewer.reprojectDepth(cam)) || planeDepthFor(cam.pose(), cam.target, cam.sceneScale);
    // Free moves: a brisk walk with a scale, else a quarter of the scene scale a second (flying's).
    this.speed = this.scaleKnown ? WALK_METRES_PER_SECOND * this.unitsPerMetre : cam.sceneScale / 4;
    this.session = null;
    this.gl = null;
    this.drawer = null;
    this.space = null;
    this.anchor = null; // world-from-XR (stereo.js xrAnchor), made at the first pose
    this.source = null; // the newest frame's eyes: { stereo, eyes: [left, right] } (see _sourceOf)
    this.size = null; // the stream's size asked for (Resize)
    this.lastViews = null; // the newest views (drawn again while tracking is lost)
    this.lastHead = null; // the head's newest world pose
    this.lastSentKey = '';
    this.forceSend = true;
    this.lastTime = null;
    this.frameMs = 0; // the display frames' interval, smoothed (where the session has no frameRate)
    this.captures = [];
    this.ended = null;
    this.stats = { xrFrames: 0, posesSent: 0, frames: 0, stereoFrames: 0, moved: 0, lastFrame: null, lastDraw: null };
    this._loop = (t, frame) => this._onXrFrame(t, frame);
  }

  // Starts the immersive session (a user gesture must be on the stack for a real headset);
  // rejects when the browser refuses it or has no WebGL2.
  async start() {
    const xr = globalThis.navigator && navigator.xr;
    if (!xr) throw new Error('this browser has no WebXR');
    const session = await xr.requestSession('immersive-vr', { optionalFeatures: ['local-floor'] });
    try {
      // Its own canvas: the view's canvas stays the page's (2D), and the XR layer needs a
      // WebGL context made for the headset's GPU (xrCompatible).
      const canvas = document.createElement('canvas');
      const gl = canvas.getContext('webgl2', { xrCompatible: true, alpha: false, antialias: false, depth: false, stencil: false });
      if (!gl) throw new Error('no WebGL2 for the headset');
      if (gl.makeXRCompatible) await gl.makeXRCompatible();
      this.drawer = new EyeDrawer(gl);
      const layer = new globalThis.XRWebGLLayer(session, gl, { antialias: false, depth: false, alpha: false });
      session.updateRenderState({ baseLayer: layer });
      // Floor-level where the headset knows the floor; else the head's start.
      this.space = await session.requestReferenceSpace('local-floor').catch(() => session.requestReferenceSpace('local'));
      this.gl = gl;
      this.canvas = canvas;
    } catch (e) {
      await session.end().catch(() => {});
      throw e;
    }
    this.session = session;
    this.ended = new Promise((resolve) => session.addEventListener('end', () => resolve(this._onEnd()), { once: true }));
    session.requestAnimationFrame(this._loop);
  }

  // Ends the session; resolves once the page has its view back.
  end() {
    if (!this.session) return Promise.resolve();
    this.session.end().catch(() => {}); // already ending: the 'end' event comes anyway
    return this.ended;
  }

  _onEnd() {
    const head = this.lastHead;
    this.session = null;
    this.captures.splice(0).forEach((c) => c.reject(new Error('VR ended')));
    this.viewer._vrEnded(this, head);
    return head;
  }

  // The next pose goes out even if the head is still (after a Resize or a KeyFrameRequest: the
  // server renders only when a pose arrives).
  resend() {
    this.forceSend = true;
  }

  // ---- frames from the server ----

  // A decoded frame (catgs_viewer.js; the caller closes it), its decoder meta and the pose that
  // asked for it (the viewer's sentPoses entry, or null).
  takeFrame(frame, meta, sent) {
    const width = frame.displayWidth;
    const height = frame.displayHeight;
    const source = meta ? this._sourceOf(meta, sent, width, height) : null;
    if (!source) return; // a frame of unknown pose cannot be re-projected: keep the last one
    this.drawer.upload(frame);
    this.source = source;
    this.stats.frames++;
    if (source.stereo) this.stats.stereoFrames++;
    this.stats.lastFrame = {
      sequence: meta.sequence, poseSequence: meta.poseSequence, width, height, eyeWidth: meta.eyeWidth,
      leftEye: meta.leftEye, rightEye: meta.rightEye,
    };
  }

  // Each eye of a frame: { pose ({ position, orientation }), k (its intrinsics), x0, width, height
  // (its part of the frame), meta }. Stereo: the eyes the frame says it shows. Mono: the head pose
  // it shows (Frame.shown_pose, else the pose it answers) over the whole frame, for both eyes.
  _sourceOf(meta, sent, width, height) {
    if (meta.eyeWidth > 0 && meta.leftEye && meta.rightEye && 2 * meta.eyeWidth <= width) {
      const w = meta.eyeWidth;
      const eye = (e, x0) => ({ pose: e, k: eyeIntrinsics(e.angles, w, height), x0, width: w, height, meta });
      return { stereo: true, eyes: [eye(meta.leftEye, 0), eye(meta.rightEye, w)] };
    }
    const pose = meta.shownPose || sent;
    if (!pose || !(pose.fovDeg > 0)) return null;
    const e = { pose, k: intrinsicsFor(pose.fovDeg, width, height), x0: 0, width, height, meta };
    return { stereo: false, eyes: [e, e] };
  }

  // Where the re-projection's plane lies for one eye of the frame: the frame's depth at the eye's
  // centre where it carries a depth grid (depth_warp.js), else the depth at entering.
  _depthOf(e) {
    const grid = e.meta.depthGridReady;
    const d = grid ? depthAt(grid, this.drawer.width, this.drawer.height, e.x0 + e.width / 2, e.height / 2) : null;
    return d > 0 ? d : this.planeDepth;
  }

  // ---- each display frame ----

  _onXrFrame(time, frame) {
    const session = frame.session;
    session.requestAnimationFrame(this._loop);
    const layer = session.renderState.baseLayer;
    const interval = this.lastTime === null ? 0 : time - this.lastTime;
    const dt = Math.min(interval / 1000, MAX_STEP_S);
    this.lastTime = time;
    if (interval > 0 && interval < 100) this.frameMs = this.frameMs ? 0.9 * this.frameMs + 0.1 * interval : interval;
    this.stats.xrFrames++;
    const pose = frame.getViewerPose(this.space);
    let views = this.lastViews;
    if (pose) {
      const head = xrPoseOf(pose.transform);
      const cam = this.viewer.camera;
      if (!this.anchor) this.anchor = xrAnchor(cam.pose(), this.up, head, this.unitsPerMetre);
      this._walk(session, head, dt, time);
      views = pose.views.map((view) => ({ eye: view.eye, viewport: layer.getViewport(view), world: eyeViewOf(this.anchor, view) }));
      this.lastViews = views;
      this.lastHead = { ...worldPose(this.anchor, head), fovDeg: verticalFovDeg(views[0].world.angles) };
      this._askSize(views);
      this._send(views);
    }
    this.drawer.begin(layer.framebuffer, layer.framebufferWidth, layer.framebufferHeight);
    if (views) this._draw(views);
    if (this.captures.length) this._capture(layer);
  }

  // The thumbstick: a smooth step along the head's level forward (and sideways), the anchor moved
  // by it; the page's driveVr hook (catgs_viewer.js) may shorten or refuse it (walk mode's rules).
  _walk(session, head, dt, now) {
    const stick = thumbstick(session);
    const hook = this.viewer.driveVr;
    if (!stick && !hook) return;
    const h = worldPose(this.anchor, head);
    const f = level(cameraForward(h.orientation), this.up);
    const r = level(cameraRight(h.orientation), this.up);
    let delta = stick ? vscale(vadd(vscale(f, stick[1]), vscale(r, stick[0])), this.speed * dt) : [0, 0, 0];
    if (hook) {
      const own = hook({ head: h, up: this.up, stick: stick || [0, 0], delta, dt, now });
      if (own) delta = own;
    }
    const moved = vlen(delta);
    if (!(moved > 0)) return;
    this.anchor = moveAnchor(this.anchor, delta);
    this.stats.moved += moved;
  }

  // The stream's size follows the eyes' viewports (a Resize when they change).
  _askSize(views) {
    const v = views[0].viewport;
    const stereo = views.length === 2;
    const size = vrStreamSize(v.width, v.height, this.viewer.renderScale, stereo ? 2 : 1);
    const s = this.size;
    if (s && s.width === size.width && s.height === size.height) return;
    this.size = size;
    this.viewer._vrResize(size);
    this.forceSend = true;
  }

  // One Pose a display frame at most, when the head moved (or a resend was asked for): the head's
  // pose and, with two views, both eyes. The viewer leaves it out while the link is backed up.
  _send(views) {
    const left = views.find((v) => v.eye === 'left');
    const right = views.find((v) => v.eye === 'right');
    const eyes = left && right ? { left: left.world, right: right.world } : null;
    const head = this.lastHead;
    const key = JSON.stringify([head.position, head.orientation, eyes && eyes.left.position, eyes && eyes.right.orientation]);
    if (key === this.lastSentKey && !this.forceSend) return;
    const sequence = this.viewer._sendPoseMessage(head, eyes, this._displayHz());
    if (sequence === null) return;
    this.lastSentKey = key;
    this.forceSend = false;
    this.stats.posesSent++;
  }

  // The rate the headset shows frames at (Pose.display_hz: the server encodes that many a second):
  // the session's own frameRate where the browser says it (WebXR's frame rate control), else the
  // display frames' measured rate; 0 (unknown) outside the protocol's 24..240.
  _displayHz() {
    const said = this.session ? Number(this.session.frameRate) : NaN;
    const hz = said > 0 ? said : this.frameMs > 0 ? Math.round(1000 / this.frameMs) : 0;
    return hz >= MIN_DISPLAY_HZ && hz <= MAX_DISPLAY_HZ ? hz : 0;
  }

  // Each view: its eye's part of the newest frame, re-projected from the eye the frame shows to
  // the eye's current view (the frame's pixel under each display pixel: the inverse homography).
  _draw(views) {
    const src = this.source;
    if (!src) return;
    const draws = [];
    for (const v of views) {
      const e = src.eyes[v.eye === 'right' ? 1 : 0];
      const vp = v.viewport;
      const depth = this._depthOf(e);
      const H = reprojectionK(e.pose, v.world, depth, e.k, eyeIntrinsics(v.world.angles, vp.width, vp.height));
      const toFrame = invert3(H);
      if (!toFrame) continue;
      this.drawer.drawEye(vp, toFrame, e);
      draws.push({ eye: v.eye, viewport: { x: vp.x, y: vp.y, width: vp.width, height: vp.height }, H, depth, frameSequence: e.meta.sequence });
    }
    this.stats.lastDraw = draws;
  }

  // Test hook: the layer's pixels as this display frame drew them.
  _capture(layer) {
    const gl = this.gl;
    const w = layer.framebufferWidth;
    const h = layer.framebufferHeight;
    const px = new Uint8Array(w * h * 4);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    // GL rows go bottom-up: top-down for an ImageData.
    const rgba = new Uint8ClampedArray(w * h * 4);
    for (let y = 0; y < h; y++) rgba.set(px.subarray((h - 1 - y) * w * 4, (h - y) * w * 4), y * w * 4);
    const shot = { width: w, height: h, rgba, ...this.snapshot() };
    this.captures.splice(0).forEach((c) => c.resolve(shot));
  }

  // Resolves with the next display frame's pixels ({ width, height, rgba (top-down) } and
  // snapshot()'s state at that frame).
  capture() {
    return new Promise((resolve, reject) => this.captures.push({ resolve, reject }));
  }

  // The session's state, for tests and stats.
  snapshot() {
    const s = this.stats;
    const copy = (v) => (v === null || v === undefined ? null : JSON.parse(JSON.stringify(v)));
    return {
      active: !!this.session,
      xrFrames: s.xrFrames,
      posesSent: s.posesSent,
      frames: s.frames,
      stereoFrames: s.stereoFrames,
      moved: s.moved,
      size: copy(this.size),
      head: copy(this.lastHead),
      views: this.lastViews ? this.lastViews.map((v) => copy({ eye: v.eye, viewport: { x: v.viewport.x, y: v.viewport.y, width: v.viewport.width, height: v.viewport.height }, world: v.world })) : null,
      lastFrame: copy(s.lastFrame),
      lastDraw: copy(s.lastDraw),
      planeDepth: this.planeDepth,
      unitsPerMetre: this.unitsPerMetre,
    };
  }
}
