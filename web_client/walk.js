// Walk mode (issue 38): the camera stays at eye height above the ground under it and stops at
// walls, both sensed with the server's depth probe (DepthRequest): one probe looks straight
// down from the camera (the ground), one looks along the way the camera is walking (a wall).
// Keys as in games: W/S or Up/Down walk forward/back, A/D or Left/Right step sideways, Shift runs;
// dragging looks around (the orbit centre sits just in front of the camera); on touch the pad at
// the bottom left walks (drag from its centre).
//
// Eye height: 1.6 m when the scene has a scale (metres per unit), else a tenth of Welcome's
// scene_scale; at least 0.4 units (twice the near plane, which the probes cannot see within). The probes refresh about 5 times a second each while walking (10 DepthRequests a
// second, within the server's default limit of 20): between answers the last distances hold.

import { cameraForward, cameraRight, lookAt, vadd, vdot, vlen, vnorm, vscale, vsub } from './camera.js';
import { alongGround, walkStep } from './annotations.js';

const PROBE_INTERVAL_MS = 200;
const PROBE_SIZE = 64; // the probes' views: 64 x 64 pixels, the pixel at the centre
// The renderer culls Gaussians nearer than this (docs/DESIGN.md "Forward model").
const NEAR_PLANE = 0.2;

export class WalkMode {
  // app: { camera(), probePose(pose, width, height, x, y) -> Promise<DepthResult>, metresPerUnit(),
  //        notice(text, level, ms) }
  constructor(app, pad) {
    this.app = app;
    this.on = false;
    this.ground = Infinity; // distance to the ground below, world units (Infinity: none seen)
    this.wall = Infinity; // distance to a wall ahead along the last walking direction
    this.wallDir = null;
    this.inFlight = 0;
    this.lastProbeMs = -Infinity;
    this.pad = pad;
    this.padVector = [0, 0]; // touch pad: [right, forward] in -1..1
    this.blocked = false; // the last step was stopped by a wall
    if (pad) this._wirePad(pad);
  }

  // At least twice the renderer's near plane: the probes cannot see what is nearer than it.
  eyeHeight(cam) {
    const mpu = this.app.metresPerUnit();
    return Math.max(mpu ? 1.6 / mpu : cam.sceneScale * 0.1, 2 * NEAR_PLANE);
  }

  // How far short of a wall the camera stops: a quarter of the eye height, and beyond the near
  // plane (a wall nearer than it is culled, and the camera would walk through).
  radius(cam) {
    return Math.max(this.eyeHeight(cam) * 0.25, 1.5 * NEAR_PLANE);
  }

  toggle(force) {
    const cam = this.app.camera();
    this.on = force ?? !this.on;
    if (this.pad) this.pad.hidden = !this.on;
    if (this.on && cam) {
      // Look level, around a point just in front of the camera (drag then turns the head).
      const f = alongGround(cameraForward(cam.orientation), cam.up);
      if (vlen(f) > 1e-6) {
        const target = vadd(cam.position, f);
        cam.orientation = lookAt(cam.position, target, cam.up);
      }
      cam.target = vadd(cam.position, vscale(cameraForward(cam.orientation), cam.sceneScale * 0.01));
      cam.version++;
      this.ground = Infinity;
      this.wall = Infinity;
      this.lastProbeMs = -Infinity;
    }
    return this.on;
  }

  // Probes: ground straight down, wall along `dir` (unit, along the ground).
  _probe(cam, now, dir) {
    if (this.inFlight > 0 || now - this.lastProbeMs < PROBE_INTERVAL_MS) return;
    this.lastProbeMs = now;
    const c = PROBE_SIZE / 2;
    const down = vscale(cam.up, -1);
    // Looking down, the image's "up" is the camera's forward along the ground.
    const ahead = vlen(alongGround(cameraForward(cam.orientation), cam.up)) > 1e-6
      ? vnorm(alongGround(cameraForward(cam.orientation), cam.up)) : cameraRight(cam.orientation);
    const groundPose = { position: cam.position, orientation: lookAt(cam.position, vadd(cam.position, down), ahead), fovDeg: 30 };
    const at = dir || ahead;
    const wallPose = { position: cam.position, orientation: lookAt(cam.position, vadd(cam.position, at), cam.up), fovDeg: 30 };
    this.inFlight = 2;
    const done = () => this.inFlight--;
    // An answer describes the camera where it was when asked: the walk since then is taken off.
    const from = cam.position.slice();
    const since = (axis) => vdot(vsub(this.app.camera().position, from), axis);
    this.app.probePose(groundPose, PROBE_SIZE, PROBE_SIZE, c, c).then((r) => {
      this.ground = r && r.hit ? r.depth + since(cam.up) : Infinity;
    }).catch(() => {}).finally(done);
    this.app.probePose(wallPose, PROBE_SIZE, PROBE_SIZE, c, c).then((r) => {
      this.wall = r && r.hit ? r.depth - since(at) : Infinity;
      this.wallDir = at;
    }).catch(() => {}).finally(done);
  }

  // One animation frame: keys (Controls.keys) and the pad move the camera along the ground.
  update(dt, keys, shift, now) {
    const cam = this.app.camera();
    if (!this.on || !cam) return;
    const k = (code) => (keys.has(code) ? 1 : 0);
    const fwd = k('KeyW') + k('ArrowUp') - k('KeyS') - k('ArrowDown') + this.padVector[1];
    const side = k('KeyD') + k('ArrowRight') - k('KeyA') - k('ArrowLeft') + this.padVector[0];
    const f = vnorm(alongGround(cameraForward(cam.orientation), cam.up));
    const r = vnorm(alongGround(cameraRight(cam.orientation), cam.up));
    let move = vadd(vscale(f, Math.max(-1, Math.min(1, fwd))), vscale(r, Math.max(-1, Math.min(1, side))));
    const len = vlen(move);
    const dir = len > 1e-6 ? vscale(move, 1 / len) : null;
    this._probe(cam, now, dir);
    const eye = this.eyeHeight(cam);
    const speed = eye * 1.0 * (shift ? 2.5 : 1); // about 1.6 m/s, running 4 m/s
    move = dir ? vscale(dir, speed * Math.min(dt, 0.1)) : [0, 0, 0];
    // The wall distance holds for the direction it was probed in; another direction is unknown
    // until its probe answers (at most 200 ms of walking, a third of an eye height).
    const sameDir = dir && this.wallDir && vdot(dir, this.wallDir) > 0.9;
    const before = cam.position;
    const next = walkStep(before, move, cam.up, {
      wallDistance: sameDir ? this.wall : Infinity,
      groundDistance: this.ground,
      eyeHeight: eye,
      radius: this.radius(cam),
      ease: Math.min(1, dt * 5),
    });
    this.blocked = !!dir && vlen(alongGround(vsub(next, before), cam.up)) < 1e-9;
    const delta = vsub(next, before);
    if (vlen(delta) > 0) {
      cam.position = next;
      cam.target = vadd(cam.target, delta);
      cam.version++;
      // The probes' answers are up to a few hundred ms old: carry them along with the move, so a
      // static floor and wall stay where they were measured until the next answer.
      if (Number.isFinite(this.ground)) this.ground += vdot(delta, cam.up);
      if (Number.isFinite(this.wall) && this.wallDir) this.wall -= vdot(delta, this.wallDir);
    }
  }

  // A depth for re-projecting the shown frame while walking: the wall ahead when one was seen,
  // else the scene scale (the orbit centre sits just in front of the camera in walk mode).
  sceneDepth(cam) {
    return Number.isFinite(this.wall) && this.wall > NEAR_PLANE ? this.wall : cam.sceneScale;
  }

  snapshot() {
    const cam = this.app.camera();
    return { on: this.on, eyeHeight: cam ? this.eyeHeight(cam) : null, radius: cam ? this.radius(cam) : null, ground: Number.isFinite(this.ground) ? this.ground : null, wall: Number.isFinite(this.wall) ? this.wall : null, blocked: this.blocked };
  }

  _wirePad(pad) {
    let id = null;
    const set = (e) => {
      const b = pad.getBoundingClientRect();
      const x = (e.clientX - (b.left + b.width / 2)) / (b.width / 2);
      const y = (e.clientY - (b.top + b.height / 2)) / (b.height / 2);
      this.padVector = [Math.max(-1, Math.min(1, x)), Math.max(-1, Math.min(1, -y))];
    };
    pad.addEventListener('pointerdown', (e) => {
      id = e.pointerId;
      pad.setPointerCapture(id);
      set(e);
      e.preventDefault();
    });
    pad.addEventListener('pointermove', (e) => e.pointerId === id && set(e));
    const end = (e) => {
      if (e.pointerId !== id) return;
      id = null;
      this.padVector = [0, 0];
    };
    pad.addEventListener('pointerup', end);
    pad.addEventListener('pointercancel', end);
  }
}
