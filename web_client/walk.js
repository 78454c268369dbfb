// Walk mode (issues 38 and 64): the camera stays at eye height above the ground under it and
// stops at obstacles (walls, trunks, plants) and at the edge of the ground, all sensed with the
// server's depth probe (DepthRequest). Keys as in games: W/S or Up/Down walk forward/back, A/D or
// Left/Right step sideways, Shift runs; dragging looks around (the orbit centre sits just in
// front of the camera); on touch the pad at the bottom left walks (drag from its centre).
//
// Eye height: 1.6 m when the scene has a scale (metres per unit), else a tenth of Welcome's
// scene_scale; at least 0.4 units (twice the near plane, which the probes cannot see within).
//
// While walking, a "look" (annotations.js walkProbes: the ground under the eye, the ground an eye
// height ahead, level probes from the eye and from a quarter of the eye height above the ground,
// along the way) goes out at most 4 times a second (16 DepthRequests a second, within the
// server's default limit of 20; standing, the ground under the eye alone, twice a second; while
// landing, the ground under and the room above). Its answers make a plan (walkPlan) and the
// camera never goes further than the plan proved free: past what the level probes saw (less a
// stop distance), past the ground the look checked, or at all while the ground ahead is missing
// or more than a step up or down. A move in another direction, or further, waits for the next
// look (before issue 64 a step went on the last answer, up to 200 ms old, or on none for a new
// direction). Near an edge or a step, the next look checks the ground nearer (half as far, down
// to a quarter of the eye height), so the camera comes up to it. Looks alternate between two
// rolls of the views up and down, and the ground counts once both agree (walkPlan says why).

import { cameraForward, cameraRight, lookAt, vadd, vdot, vlen, vnorm, vscale, vsub } from './viewer/viewer.js';
import { alongGround, walkGroundAt, walkLookDistance, walkPlan, walkProbes, walkSizes, walkStep } from './annotations.js';

const LOOK_INTERVAL_MS = 250; // walking: one look (4 probes) at most every 250 ms
const IDLE_INTERVAL_MS = 500; // standing: the ground under the eye, twice a second
// The renderer culls Gaussians nearer than this (docs/DESIGN.md "Forward model").
const NEAR_PLANE = 0.2;
const TRACE_MAX = 5000;

export class WalkMode {
  // app: { camera(), probePose(pose, width, height, x, y) -> Promise<DepthResult>, metresPerUnit(),
  //        notice(text, level, ms) }
  constructor(app, pad) {
    this.app = app;
    this.on = false;
    this.plan = null; // the last look's plan (annotations.js walkPlan)
    this.inFlight = false;
    this.generation = 0; // answers of a look from before the last toggle are dropped
    this.lastLookMs = -Infinity;
    this.looks = 0;
    this.roll = 0; // the roll of the vertical probe views, alternating look by look
    this.pad = pad;
    this.padVector = [0, 0]; // touch pad: [right, forward] in -1..1
    this.blocked = false; // the last step was stopped by an obstacle, an edge or a step
    this.waiting = false; // the last step waited for a look
    this.trace = null; // an array of steps while the test hook traces
    if (pad) this._wirePad(pad);
  }

  // At least twice the renderer's near plane: the probes cannot see what is nearer than it.
  eyeHeight(cam) {
    const mpu = this.app.metresPerUnit();
    return Math.max(mpu ? 1.6 / mpu : cam.sceneScale * 0.1, 2 * NEAR_PLANE);
  }

  sizes(cam) {
    return walkSizes(this.eyeHeight(cam), NEAR_PLANE);
  }

  // How far short of an obstacle the camera stops (annotations.js walkSizes).
  radius(cam) {
    return this.sizes(cam).radius;
  }

  toggle(force) {
    const cam = this.app.camera();
    this.on = force ?? !this.on;
    if (this.pad) this.pad.hidden = !this.on;
    this.generation++;
    this.plan = null;
    this.inFlight = false;
    this.lastLookMs = -Infinity;
    this.blocked = false;
    this.waiting = false;
    if (this.on && cam) {
      // Look level, around a point just in front of the camera (drag then turns the head).
      const f = alongGround(cameraForward(cam.orientation), cam.up);
      if (vlen(f) > 1e-6) {
        const target = vadd(cam.position, f);
        cam.orientation = lookAt(cam.position, target, cam.up);
      }
      cam.target = vadd(cam.position, vscale(cameraForward(cam.orientation), cam.sceneScale * 0.01));
      cam.version++;
    }
    return this.on;
  }

  // A look along `dir` (unit, along the ground; null: the ground under the eye only).
  _look(cam, now, dir, sizes) {
    const last = this.plan;
    const origin = cam.position.slice();
    const ground = last ? walkGroundAt(last, origin, cam.up) : null;
    // Landing: until two looks agree on the ground and the eye is near its height above it.
    const landing = !last || !last.confirmed || (ground !== null && Math.abs(vdot(origin, cam.up) - ground - sizes.eye) > 0.2 * sizes.eye);
    if (this.inFlight || now - this.lastLookMs < (dir || landing ? LOOK_INTERVAL_MS : IDLE_INTERVAL_MS)) return;
    // Near an edge or a step, look half as far each time (down to a quarter of the eye height).
    const look = walkLookDistance(last, dir, sizes);
    const way = landing ? null : dir;
    const roll = (this.roll = 1 - this.roll); // alternate: see annotations.js walkPlan
    const probes = walkProbes(origin, cam.up, sizes, { dir: way, look, ground, landing, roll });
    this.inFlight = true;
    this.lastLookMs = now;
    const generation = this.generation;
    const up = cam.up.slice();
    const asked = performance.now();
    Promise.all(probes.map((p) => this.app.probePose(p.pose, p.size, p.size, p.size / 2, p.size / 2).catch(() => null)))
      .then((results) => {
        if (generation !== this.generation) return;
        const answers = {};
        probes.forEach((p, i) => (answers[p.name] = results[i]));
        this.plan = walkPlan(origin, up, sizes, answers, { dir: way, look, previous: this.plan, roll, landing });
        this.plan.ms = performance.now() - asked;
        this.looks++;
      })
      .finally(() => {
        if (generation === this.generation) this.inFlight = false;
      });
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
    const move = vadd(vscale(f, Math.max(-1, Math.min(1, fwd))), vscale(r, Math.max(-1, Math.min(1, side))));
    const len = vlen(move);
    const dir = len > 1e-6 ? vscale(move, 1 / len) : null;
    const sizes = this.sizes(cam);
    this._look(cam, now, dir, sizes);
    const speed = sizes.eye * (shift ? 2.5 : 1); // about 1.6 m/s, running 4 m/s
    const step = Math.min(dt, 0.1);
    const before = cam.position;
    const r2 = walkStep(before, dir, dir ? speed * step : 0, cam.up, sizes, this.plan, step);
    this.blocked = r2.blocked;
    this.waiting = r2.waiting;
    const delta = vsub(r2.position, before);
    if (vlen(delta) > 0) {
      cam.position = r2.position;
      cam.target = vadd(cam.target, delta);
      cam.version++;
    }
    if (this.trace && (dir || r2.moved > 0) && this.trace.length < TRACE_MAX) {
      const p = this.plan;
      this.trace.push({
        t: now, dir, position: r2.position, moved: r2.moved, blocked: r2.blocked, waiting: r2.waiting,
        plan: p && { underSeen: p.underSeen, aheadSeen: p.aheadSeen, origin: p.origin, dir: p.dir, look: p.look, free: Number.isFinite(p.free) ? p.free : null, allowed: p.allowed, reason: p.reason, confirmed: p.confirmed, ground0: p.ground0, ground1: p.ground1, ms: p.ms, ceiling: p.ceiling, roll: p.roll, pending: p.pending },
        progress: p && p.dir ? vdot(vsub(r2.position, p.origin), p.dir) : null,
      });
    }
  }

  // The test hook's trace of steps: starts a fresh one (on), or stops and returns it.
  takeTrace(on) {
    const t = this.trace || [];
    this.trace = on ? [] : null;
    return t;
  }

  // A depth for re-projecting the shown frame while walking: the obstacle ahead when one was
  // seen, else the scene scale (the orbit centre sits just in front of the camera in walk mode).
  sceneDepth(cam) {
    const w = this._wallLeft(cam);
    return w !== null && w > NEAR_PLANE ? w : cam.sceneScale;
  }

  _wallLeft(cam) {
    const p = this.plan;
    if (!p || !p.dir || !Number.isFinite(p.free)) return null;
    return p.free - vdot(vsub(cam.position, p.origin), p.dir);
  }

  snapshot() {
    const cam = this.app.camera();
    const sizes = cam ? this.sizes(cam) : null;
    const g = cam && this.plan ? walkGroundAt(this.plan, cam.position, cam.up) : null;
    return {
      on: this.on,
      eyeHeight: sizes && sizes.eye,
      radius: sizes && sizes.radius,
      step: sizes && sizes.step,
      ground: g === null || !cam ? null : vdot(cam.position, cam.up) - g, // the eye's height above the ground under it
      wall: cam ? this._wallLeft(cam) : null, // what the last look saw free ahead, from here
      reason: this.plan ? this.plan.reason : '',
      blocked: this.blocked,
      waiting: this.waiting,
      looks: this.looks,
    };
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

// VR (issue 94): the thumbstick walks by walk mode's rules, a WalkMode of its own on a stand-in
// camera that is the head, set again each display frame (the viewer's driveVr hook, xr.js). Its
// looks probe from the head; its plan stops the step short of walls and plants, at edges and at
// steps; the stick is its pad. While the stick is held the step carries walk mode's height too
// (the head eased to eye height over the ground, so a step up lifts the visitor); standing still,
// nothing moves: the headset's own height (crouching, standing up) is the visitor's.
const NO_KEYS = new Set();

export class VrWalk {
  // walk: the page's WalkMode (its app: probePose, metresPerUnit, the page's camera for the scale).
  constructor(walk) {
    const page = walk.app;
    this.head = { position: [0, 0, 0], orientation: [1, 0, 0, 0], target: [0, 0, 0], up: [0, -1, 0], sceneScale: 1, version: 0 };
    this.mode = new WalkMode({ ...page, camera: () => this.head }, null);
    this.mode.on = true;
    this.sceneScale = () => (page.camera() ? page.camera().sceneScale : 1);
    this.drive = (step) => this._drive(step);
  }

  // xr.js's step: { head (world pose), up, stick ([right, forward]), dt, now } -> the world step.
  _drive({ head, up, stick, dt, now }) {
    const h = this.head;
    h.position = head.position.slice();
    h.orientation = head.orientation.slice();
    h.target = vadd(h.position, cameraForward(h.orientation));
    h.up = up.slice();
    h.sceneScale = this.sceneScale();
    this.mode.padVector = stick;
    this.mode.update(dt, NO_KEYS, false, now);
    if (!stick[0] && !stick[1]) return [0, 0, 0];
    return vsub(h.position, head.position);
  }
}
