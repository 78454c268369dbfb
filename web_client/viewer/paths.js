// Camera paths: recorded timed poses, guided-tour waypoints, and their files (INRIA cameras.json
// and our catgs-trace), so catgs-loadgen (`--trace cameras:C.json` or `--trace FILE.trace`) and
// catgs-bench replay what a person did. Pure (no DOM): node unit-tests it.
//
// A pose here is { position: [x, y, z], orientation: [w, x, y, z] (camera-to-world, OpenCV axes),
// fovDeg (vertical) }, as camera.js and the wire protocol have it.

import { intrinsicsFor, qnorm, quatFromAxes } from './camera.js';

// catgs-loadgen and catgs-bench play a cameras.json at this many seconds per view
// (tools/loadgen/load_session.cpp kSecondsPerView, tools/bench/catgs_bench.cpp): a recording
// exported with one view per this interval replays at the speed it was recorded.
export const LOADGEN_SECONDS_PER_VIEW = 0.5;
// A guided tour's pace between two waypoints.
export const TOUR_SECONDS_PER_VIEW = 2.0;

// ---- quaternion <-> rotation matrix (rows of camera-to-world, as cameras.json stores it) ----

export function matrixFromQuat(q) {
  const [w, x, y, z] = qnorm(q);
  return [
    [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
    [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
    [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
  ];
}

export function quatFromMatrix(m) {
  // Columns are the camera's right, down and forward axes in world coordinates.
  const col = (c) => [m[0][c], m[1][c], m[2][c]];
  return quatFromAxes(col(0), col(1), col(2));
}

const finite = (v) => typeof v === 'number' && Number.isFinite(v);

// ---- recording and timed playback ----

export class PathRecorder {
  constructor() {
    this.samples = []; // { t (s from the first sample), position, orientation, fovDeg }
    this.t0 = null;
    this.lastSeenT = 0; // the time of the latest add(), changed or not
  }

  // Adds the pose at page time nowMs unless it equals the previous sample: a still camera adds
  // nothing but, when it moves again, the pose it held until the previous call, so playback
  // (which interpolates between samples) holds still and then moves as recorded, rather than
  // gliding across the pause.
  // The page's times come from two clocks: requestAnimationFrame's frame start and
  // performance.now() (timers, clicks), and a frame's start can precede a click handled just
  // before its callbacks. So a time before the latest one seen counts as that one: the path's
  // time never runs backwards, which trace readers and the server's export refuse.
  add(nowMs, pose) {
    if (this.t0 === null) this.t0 = nowMs;
    const t = Math.max((nowMs - this.t0) / 1000, this.lastSeenT);
    const last = this.samples[this.samples.length - 1];
    const seen = this.lastSeenT;
    this.lastSeenT = t;
    if (last && samePose(last, pose)) return false;
    if (last && seen > last.t) this.samples.push({ t: seen, ...clonePose(last) });
    this.samples.push({ t, ...clonePose(pose) });
    return true;
  }

  get duration() {
    return this.samples.length ? this.samples[this.samples.length - 1].t : 0;
  }
}

function clonePose(p) {
  return { position: p.position.slice(), orientation: p.orientation.slice(), fovDeg: p.fovDeg };
}

function samePose(a, b) {
  return a.fovDeg === b.fovDeg && a.position.every((v, i) => v === b.position[i]) &&
    a.orientation.every((v, i) => v === b.orientation[i]);
}

// The pose of a timed path at time t (s): linear position and fov, slerp orientation between the
// samples around t; clamped at the ends.
export function poseAtTime(samples, t) {
  if (!samples.length) throw new Error('empty path');
  if (t <= samples[0].t) return clonePose(samples[0]);
  const last = samples[samples.length - 1];
  if (t >= last.t) return clonePose(last);
  let lo = 0;
  let hi = samples.length - 1;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (samples[mid].t <= t) lo = mid;
    else hi = mid;
  }
  const a = samples[lo];
  const b = samples[hi];
  const u = b.t > a.t ? (t - a.t) / (b.t - a.t) : 0;
  return {
    position: a.position.map((v, i) => v + u * (b.position[i] - v)),
    orientation: qnorm(slerp(a.orientation, b.orientation, u)),
    fovDeg: a.fovDeg + u * (b.fovDeg - a.fovDeg),
  };
}

// ---- guided tour: the core's interpolation, mirrored ----

// glm::slerp (glm 0.9.9.8, glm/ext/quaternion_common.inl), which the core's interpolate_views
// uses: shortest arc (y negated when the dot product is negative), plain lerp when the two are
// within epsilon of each other. Quaternions [w, x, y, z].
export function slerp(x, y, a) {
  let z = y;
  let cosTheta = x[0] * y[0] + x[1] * y[1] + x[2] * y[2] + x[3] * y[3];
  if (cosTheta < 0) {
    z = y.map((v) => -v);
    cosTheta = -cosTheta;
  }
  if (cosTheta > 1 - 1.1920929e-7) return x.map((v, i) => v + a * (z[i] - v)); // float epsilon
  const angle = Math.acos(cosTheta);
  const s = Math.sin(angle);
  return x.map((v, i) => (Math.sin((1 - a) * angle) * v + Math.sin(a * angle) * z[i]) / s);
}

// Centripetal Catmull-Rom (alpha = 0.5, Barry-Goldman pyramid) between p1 and p2, u in [0, 1]:
// the formula of centripetal_catmull_rom in render_core/camera/trace.cpp, term for term.
export function centripetalCatmullRom(p0, p1, p2, p3, u) {
  const dist = (a, b) => Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);
  const knot = (a, b) => Math.max(Math.sqrt(dist(a, b)), 1e-4);
  const t0 = 0;
  const t1 = t0 + knot(p0, p1);
  const t2 = t1 + knot(p1, p2);
  const t3 = t2 + knot(p2, p3);
  const t = t1 + u * (t2 - t1);
  const mix = (pa, ta, pb, tb) => pa.map((v, i) => ((tb - t) * v + (t - ta) * pb[i]) / (tb - ta));
  const a1 = mix(p0, t0, p1, t1);
  const a2 = mix(p1, t1, p2, t2);
  const a3 = mix(p2, t2, p3, t3);
  const b1 = mix(a1, t0, a2, t2);
  const b2 = mix(a2, t1, a3, t3);
  return mix(b1, t1, b2, t2);
}

// The tour's pose at time t (s) through waypoints `keys`, `secondsPerView` apart: what
// interpolate_views (render_core/camera/trace.cpp) computes for the same keys at u = fraction of
// the segment, with reflected end points, slerp between the two keys' orientations, and a linear
// field of view (the core interpolates fy linearly; for one image height that is the same as
// interpolating the focal length, so the fov comes from it).
export function tourPoseAt(keys, t, secondsPerView = TOUR_SECONDS_PER_VIEW) {
  if (keys.length < 2) throw new Error('a tour needs at least 2 waypoints');
  const segments = keys.length - 1;
  const x = Math.min(Math.max(t / secondsPerView, 0), segments);
  const s = Math.min(Math.floor(x), segments - 1);
  const u = x - s;
  const pos = keys.map((k) => k.position);
  const p1 = pos[s];
  const p2 = pos[s + 1];
  const p0 = s > 0 ? pos[s - 1] : p1.map((v, i) => 2 * v - p2[i]);
  const p3 = s + 2 < pos.length ? pos[s + 2] : p2.map((v, i) => 2 * v - p1[i]);
  const f = (k) => 1 / (2 * Math.tan((k.fovDeg * Math.PI) / 360)); // focal length per unit height
  const fy = f(keys[s]) + u * (f(keys[s + 1]) - f(keys[s]));
  return {
    position: centripetalCatmullRom(p0, p1, p2, p3, u),
    orientation: qnorm(slerp(keys[s].orientation, keys[s + 1].orientation, u)),
    fovDeg: (2 * Math.atan(1 / (2 * fy)) * 180) / Math.PI,
  };
}

export const tourDuration = (keys, secondsPerView = TOUR_SECONDS_PER_VIEW) =>
  Math.max(0, keys.length - 1) * secondsPerView;

// ---- files ----

// Samples a timed path every `interval` seconds (the last sample always included): a recording
// turned into cameras.json key views that catgs-loadgen replays at LOADGEN_SECONDS_PER_VIEW each.
export function resample(samples, interval = LOADGEN_SECONDS_PER_VIEW) {
  if (!samples.length) return [];
  const out = [];
  const end = samples[samples.length - 1].t;
  for (let t = samples[0].t; t < end - 1e-9; t += interval) out.push({ t, ...poseAtTime(samples, t) });
  out.push({ t: end, ...clonePose(samples[samples.length - 1]) });
  return out;
}

// INRIA cameras.json (the 3DGS training output; render_core/camera/trace.cpp load_inria_cameras
// reads it): [{id, img_name, width, height, position, rotation (3x3 camera-to-world, rows), fx,
// fy}], principal point at the image centre.
export function toInriaCameras(poses, width, height, name = 'view') {
  return poses.map((p, id) => {
    const { fx, fy } = intrinsicsFor(p.fovDeg, width, height);
    return {
      id,
      // A hotspot tour's waypoint names its hotspot (annotations.js), so tour.json shows which.
      img_name: p.hotspot ? `hotspot_${p.hotspot}` : `${name}_${String(id).padStart(4, '0')}`,
      width,
      height,
      position: p.position.slice(),
      rotation: matrixFromQuat(p.orientation),
      fx,
      fy,
    };
  });
}

// Reads cameras.json text into poses (the vertical fov from fy and height). Throws an Error
// naming the entry for anything malformed, as the C++ reader does.
export function fromInriaCameras(text) {
  let doc;
  try {
    doc = JSON.parse(text);
  } catch (e) {
    throw new Error(`cameras.json: malformed JSON: ${e.message}`);
  }
  if (!Array.isArray(doc) || doc.length === 0) throw new Error('cameras.json: expected a non-empty JSON list of cameras');
  return doc.map((c, k) => {
    const bad = (why) => new Error(`cameras.json: camera entry ${k}: ${why}`);
    if (!c || typeof c !== 'object') throw bad('not an object');
    if (!(Number.isInteger(c.height) && c.height > 0) || !(finite(c.fy) && c.fy > 0)) throw bad('bad height or fy');
    if (!Array.isArray(c.position) || c.position.length !== 3 || !c.position.every(finite)) throw bad('bad position');
    const R = c.rotation;
    if (!Array.isArray(R) || R.length !== 3 || !R.every((r) => Array.isArray(r) && r.length === 3 && r.every(finite))) {
      throw bad('bad rotation (3x3 rows expected)');
    }
    const pose = {
      position: c.position.slice(),
      orientation: quatFromMatrix(R),
      fovDeg: (2 * Math.atan(c.height / (2 * c.fy)) * 180) / Math.PI,
    };
    // A hotspot tour's waypoint (toInriaCameras): the tour shows that hotspot's card there.
    if (typeof c.img_name === 'string' && c.img_name.startsWith('hotspot_')) pose.hotspot = c.img_name.slice(8);
    return pose;
  });
}

const g = (v) => Number(v.toPrecision(9)).toString();

// Our trace file (render_core/camera/trace.h write_trace / read_trace):
//   catgs-trace 1
//   <time_s> <px> <py> <pz> <qw> <qx> <qy> <qz> <fx> <fy> <cx> <cy> <width> <height>
export function toTraceFile(samples, width, height) {
  const lines = ['catgs-trace 1', '# time_s px py pz qw qx qy qz fx fy cx cy width height (recorded in the CaT-GS viewer)'];
  for (const s of samples) {
    const k = intrinsicsFor(s.fovDeg, width, height);
    lines.push([s.t, ...s.position, ...qnorm(s.orientation), k.fx, k.fy, k.cx, k.cy].map(g).join(' ') + ` ${width} ${height}`);
  }
  return lines.join('\n') + '\n';
}

export function fromTraceFile(text) {
  const samples = [];
  let magic = false;
  const lines = text.split('\n');
  for (let n = 0; n < lines.length; n++) {
    const line = lines[n].replace(/#.*/, '').trim();
    if (!line) continue;
    const bad = (why) => new Error(`trace line ${n + 1}: ${why}`);
    const f = line.split(/\s+/);
    if (!magic) {
      if (f[0] !== 'catgs-trace' || f[1] !== '1') throw bad("expected 'catgs-trace 1'");
      magic = true;
      continue;
    }
    if (f.length !== 14) throw bad('expected 14 fields');
    const v = f.map(Number);
    if (!v.every(Number.isFinite)) throw bad('not a number');
    const [t, px, py, pz, qw, qx, qy, qz, , fy, , , , height] = v;
    if (!(fy > 0) || !(height > 0)) throw bad('bad intrinsics or size');
    if (samples.length && t < samples[samples.length - 1].t) throw bad('time goes backwards');
    samples.push({ t, position: [px, py, pz], orientation: qnorm([qw, qx, qy, qz]), fovDeg: (2 * Math.atan(height / (2 * fy)) * 180) / Math.PI });
  }
  if (!magic) throw new Error("empty trace file (no 'catgs-trace 1' line)");
  if (!samples.length) throw new Error('trace file has no cameras');
  return samples;
}
