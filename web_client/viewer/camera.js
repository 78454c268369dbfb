// Camera maths and the orbit/pan/zoom/fly camera state. Pure (no DOM), so node can unit-test it.
//
// Conventions follow the wire protocol and render_core/camera/camera.h: OpenCV camera axes
// (x right, y down, z forward); a pose's orientation is the camera-to-world unit quaternion
// [w, x, y, z]; vectors are plain [x, y, z] arrays.

export const vadd = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
export const vsub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
export const vscale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
export const vdot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
export const vcross = (a, b) => [
  a[1] * b[2] - a[2] * b[1],
  a[2] * b[0] - a[0] * b[2],
  a[0] * b[1] - a[1] * b[0],
];
export const vlen = (a) => Math.hypot(a[0], a[1], a[2]);
export function vnorm(a) {
  const l = vlen(a);
  return l > 0 ? vscale(a, 1 / l) : [0, 0, 0];
}

export function qnorm(q) {
  const l = Math.hypot(q[0], q[1], q[2], q[3]);
  if (!(l > 0) || !Number.isFinite(l)) return [1, 0, 0, 0];
  // Keep w >= 0 so equal rotations have one spelling (handy for tests and logs).
  const s = q[0] < 0 ? -1 / l : 1 / l;
  return [q[0] * s, q[1] * s, q[2] * s, q[3] * s];
}

// Hamilton product a * b (apply b first, then a).
export function qmul(a, b) {
  const [aw, ax, ay, az] = a;
  const [bw, bx, by, bz] = b;
  return [
    aw * bw - ax * bx - ay * by - az * bz,
    aw * bx + ax * bw + ay * bz - az * by,
    aw * by - ax * bz + ay * bw + az * bx,
    aw * bz + ax * by - ay * bx + az * bw,
  ];
}

export function qfromAxisAngle(axis, angle) {
  const n = vnorm(axis);
  const s = Math.sin(angle / 2);
  return [Math.cos(angle / 2), n[0] * s, n[1] * s, n[2] * s];
}

// Rotates v by unit quaternion q (v' = q v q*), expanded to avoid building a matrix.
export function qrotate(q, v) {
  const [w, x, y, z] = q;
  const u = [x, y, z];
  const t = vscale(vcross(u, v), 2);
  return vadd(vadd(v, vscale(t, w)), vcross(u, t));
}

// Camera axes in world coordinates for a camera-to-world orientation.
export const cameraRight = (q) => qrotate(q, [1, 0, 0]);
export const cameraDown = (q) => qrotate(q, [0, 1, 0]);
export const cameraForward = (q) => qrotate(q, [0, 0, 1]);

// Camera-to-world quaternion from orthonormal right/down/forward columns (Shepperd's method).
export function quatFromAxes(r, d, f) {
  const m00 = r[0], m01 = d[0], m02 = f[0];
  const m10 = r[1], m11 = d[1], m12 = f[1];
  const m20 = r[2], m21 = d[2], m22 = f[2];
  const tr = m00 + m11 + m22;
  let q;
  if (tr > 0) {
    const s = Math.sqrt(tr + 1) * 2;
    q = [0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s];
  } else if (m00 > m11 && m00 > m22) {
    const s = Math.sqrt(1 + m00 - m11 - m22) * 2;
    q = [(m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s];
  } else if (m11 > m22) {
    const s = Math.sqrt(1 + m11 - m00 - m22) * 2;
    q = [(m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s];
  } else {
    const s = Math.sqrt(1 + m22 - m00 - m11) * 2;
    q = [(m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s];
  }
  return qnorm(q);
}

// Camera at `eye` looking at `target` with world `up` (OpenCV axes: image y points away from up).
export function lookAt(eye, target, up) {
  const f = vnorm(vsub(target, eye));
  let r = vcross(vscale(up, -1), f); // right = down x forward (r x d = f)
  if (vlen(r) < 1e-9) r = vcross(f, [1, 0, 0]);
  r = vnorm(r);
  const d = vcross(f, r);
  return quatFromAxes(r, d, f);
}

// Intrinsics the render core derives from a pose (Camera::from_pose): square pixels, principal
// point at the image centre, fy = height / (2 tan(vfov / 2)).
export function intrinsicsFor(fovDeg, width, height) {
  const f = height / (2 * Math.tan((fovDeg * Math.PI) / 180 / 2));
  return { fx: f, fy: f, cx: width / 2, cy: height / 2 };
}

// How far zooming out goes from the orbit target, in scene scales (Welcome.scene_scale: a typical
// viewing distance, such as the training cameras' median distance from the orbit centre, or the
// distance that frames an object whole): about 2.6 content radii of flowers_sh3 (its radius is
// scene_scale tan(30 deg)), 3.2 of the biker. Looked at on flowers_sh3 from four sides: at 1.5 the
// flower bed on its lawn from each; at 2 a haze of background Gaussians in front from one side;
// at 2.5 brown mush from two (the camera among the trees the capture saw from inside).
export const MAX_ORBIT_SCALES = 1.5;

const finite3 = (v) => Array.isArray(v) && v.length === 3 && v.every(Number.isFinite);

// Orbit camera: the pose plus a target it orbits around and a world up. Every change bumps
// `version` so the sender can tell cheaply whether a new Pose must go out.
export class OrbitCamera {
  constructor({ position, orientation, fovDeg, target, up, sceneScale }) {
    this.position = position.slice();
    this.orientation = qnorm(orientation);
    this.fovDeg = fovDeg;
    this.target = target.slice();
    this.up = vnorm(up);
    // A length that makes speeds and limits scale with the scene (units of the scene file vary).
    this.sceneScale = sceneScale > 0 ? sceneScale : 1;
    this.version = 0;
    this.rotateSpeed = 0.005; // radians per CSS pixel of drag
  }

  // Start as the server suggests: its initial pose, and the frame of Welcome's orbit_centre, up
  // and scene_scale (`frame`: any object with those fields, such as the Welcome itself): orbit
  // around the centre with up vertical; speeds scale with the scene scale (a typical viewing
  // distance). Servers without those fields (scene_scale 0): orbit around the bounds' centre, up
  // the initial camera's -y axis (3DGS scenes are usually y-down, so world +y is not up), scale
  // the bounds' diagonal.
  static fromWelcome(initialPose, bounds, frame) {
    const position = vec3Of(initialPose && initialPose.position, [0, 0, 0]);
    const orientation = qnorm(quatOf(initialPose && initialPose.orientation));
    let fovDeg = initialPose && initialPose.vertical_fov_deg;
    if (!(fovDeg > 1 && fovDeg < 170)) fovDeg = 60;
    const fromFrame = frameOf(frame);
    if (fromFrame) return new OrbitCamera({ position, orientation, fovDeg, ...fromFrame });
    const up = vscale(cameraDown(orientation), -1);
    let target = null;
    let sceneScale = 0;
    if (bounds && bounds.min && bounds.max) {
      const lo = vec3Of(bounds.min, null);
      const hi = vec3Of(bounds.max, null);
      if (lo && hi) {
        sceneScale = vlen(vsub(hi, lo));
        if (sceneScale > 0) target = vscale(vadd(lo, hi), 0.5);
      }
    }
    if (!target || vlen(vsub(target, position)) < 1e-6) {
      // No usable bounds: orbit around a point in front of the camera.
      const dist = sceneScale > 0 ? sceneScale / 2 : 1;
      target = vadd(position, vscale(cameraForward(orientation), dist));
    }
    if (!(sceneScale > 0)) sceneScale = 2 * vlen(vsub(target, position));
    return new OrbitCamera({ position, orientation, fovDeg, target, up, sceneScale });
  }

  pose() {
    return { position: this.position.slice(), orientation: this.orientation.slice(), fovDeg: this.fovDeg };
  }

  _changed() {
    this.version++;
  }

  // Rigid rotation of the camera about the target: the camera keeps its view relative to the
  // target, so this works even when the camera does not look straight at it.
  _rotateAbout(rot) {
    const rel = qrotate(rot, vsub(this.position, this.target));
    this.position = vadd(this.target, rel);
    this.orientation = qnorm(qmul(rot, this.orientation));
  }

  // Drag by (dx, dy) pixels: the scene follows the pointer (drag right = scene turns right, drag
  // down = camera rises to look more from above).
  orbit(dx, dy) {
    if (!dx && !dy) return;
    const yaw = qfromAxisAngle(this.up, -dx * this.rotateSpeed);
    this._rotateAbout(yaw);
    const pitchAngle = -dy * this.rotateSpeed;
    if (pitchAngle) {
      const pitch = qfromAxisAngle(cameraRight(this.orientation), pitchAngle);
      const rel = qrotate(pitch, vsub(this.position, this.target));
      const elevation = vdot(vnorm(rel), this.up);
      // Stop short of the poles: past them the camera would flip upside down.
      if (Math.abs(elevation) < 0.995 || Math.abs(elevation) < Math.abs(vdot(vnorm(vsub(this.position, this.target)), this.up))) {
        this._rotateAbout(pitch);
      }
    }
    this._changed();
  }

  // Pixels to world units at the target's depth, so a pan moves the target with the pointer.
  _worldPerPixel(viewportHeightPx) {
    const depth = Math.max(vdot(vsub(this.target, this.position), cameraForward(this.orientation)), this.sceneScale * 1e-3);
    return (2 * depth * Math.tan((this.fovDeg * Math.PI) / 360)) / Math.max(viewportHeightPx, 1);
  }

  pan(dx, dy, viewportHeightPx) {
    if (!dx && !dy) return;
    const s = this._worldPerPixel(viewportHeightPx);
    const delta = vscale(vadd(vscale(cameraRight(this.orientation), dx), vscale(cameraDown(this.orientation), dy)), -s);
    this.position = vadd(this.position, delta);
    this.target = vadd(this.target, delta);
    this._changed();
  }

  // The farthest zoom-out: MAX_ORBIT_SCALES scene scales from the target. Farther out a trained
  // scene is its background seen from outside (12 wheel notches out on flowers_sh3, 3.4 scales,
  // filled the screen with brown mush).
  get maxDistance() {
    return this.sceneScale * MAX_ORBIT_SCALES;
  }

  // factor < 1 moves towards the target. Near the target it dollies on (target moves too), so
  // zooming never gets stuck. Zooming out stops at maxDistance (a camera put farther by setPose
  // may zoom in, not out).
  zoom(factor) {
    if (!(factor > 0) || factor === 1) return;
    const rel = vsub(this.position, this.target);
    const dist = vlen(rel);
    const minDist = this.sceneScale * 1e-3;
    if (factor > 1) {
      if (dist >= this.maxDistance) return;
      factor = Math.min(factor, this.maxDistance / dist);
    }
    const newDist = dist * factor;
    if (newDist < minDist && factor < 1) {
      const step = vscale(cameraForward(this.orientation), Math.max(dist * (1 - factor), minDist));
      this.position = vadd(this.position, step);
      this.target = vadd(this.target, step);
    } else {
      this.position = vadd(this.target, vscale(rel, factor));
    }
    this._changed();
  }

  // Fly: move along forward / right / up by `speed` world units per second for `dt` seconds.
  fly(dt, forward, right, up, speed) {
    if (!(dt > 0) || (!forward && !right && !up)) return;
    const s = speed * dt;
    let delta = vscale(cameraForward(this.orientation), forward * s);
    delta = vadd(delta, vscale(cameraRight(this.orientation), right * s));
    delta = vadd(delta, vscale(this.up, up * s));
    this.position = vadd(this.position, delta);
    this.target = vadd(this.target, delta);
    this._changed();
  }

  // Sets the pose outright (test hook, programmatic moves). The target stays at the same
  // distance in front of the new camera so orbiting afterwards feels continuous.
  setPose(position, orientation, fovDeg) {
    if (!finite3(position)) throw new Error('position must be 3 finite numbers');
    if (!Array.isArray(orientation) || orientation.length !== 4 || !orientation.every(Number.isFinite)) {
      throw new Error('orientation must be 4 finite numbers (w, x, y, z)');
    }
    const dist = Math.max(vlen(vsub(this.target, this.position)), this.sceneScale * 1e-3);
    this.position = position.slice();
    this.orientation = qnorm(orientation);
    if (fovDeg !== undefined && fovDeg !== null) {
      if (!(fovDeg > 1 && fovDeg < 170)) throw new Error('fovDeg must be in (1, 170)');
      this.fovDeg = fovDeg;
    }
    this.target = vadd(this.position, vscale(cameraForward(this.orientation), dist));
    this._changed();
  }
}

function vec3Of(v, fallback) {
  if (!v) return fallback;
  const a = [Number(v.x || 0), Number(v.y || 0), Number(v.z || 0)];
  return a.every(Number.isFinite) ? a : fallback;
}

// Welcome's orbit_centre, up and scene_scale as {target, up, sceneScale}, or null when the
// server sent none (older servers) or they are unusable (no positive finite scale, zero up).
function frameOf(frame) {
  if (!frame || !(Number(frame.scene_scale) > 0) || !Number.isFinite(Number(frame.scene_scale))) return null;
  const up = vec3Of(frame.up, null);
  if (!up || !(vlen(up) > 0)) return null;
  return { target: vec3Of(frame.orbit_centre, [0, 0, 0]), up, sceneScale: Number(frame.scene_scale) };
}

function quatOf(q) {
  if (!q) return [1, 0, 0, 0];
  // proto3 omits zero fields, so a missing w reads as 0 (a default-constructed Quat is invalid).
  return [Number(q.w || 0), Number(q.x || 0), Number(q.y || 0), Number(q.z || 0)];
}
