// What CatgsViewer.setPose and playPath take, turned into the protocol's poses. Pure (no DOM), so
// node unit-tests it.
//
// The frame is the wire protocol's (proto/catgs_stream.proto): world units of the scene file; a
// pose is the camera centre `position` [x, y, z], its camera-to-world rotation `orientation`
// [w, x, y, z] in OpenCV camera axes (x right, y down, z forward: the camera looks along its +z),
// and the vertical field of view `fovDeg` in degrees, in (1, 170).

import { lookAt, vlen, vsub } from './camera.js';
import { fromInriaCameras, fromTraceFile, poseAtTime, tourDuration, tourPoseAt } from './paths.js';

const finite3 = (v) => Array.isArray(v) && v.length === 3 && v.every(Number.isFinite);
const finite4 = (v) => Array.isArray(v) && v.length === 4 && v.every(Number.isFinite);

// spec: { position?, orientation? (or its other name rotation), lookAt?, up?, fovDeg? }; what it
// leaves out stays as in `current` ({ position, orientation, fovDeg, up }: the camera now).
// `lookAt` [x, y, z] turns the camera to that world point with `up` (default: the scene's up,
// Welcome.up) at the top of the image, and becomes the point orbiting turns around.
// Returns { position, orientation, fovDeg, target (the lookAt point or null) }; throws on input
// that is not a pose.
export function resolvePose(spec, current) {
  if (!spec || typeof spec !== 'object') throw new Error('setPose takes an object: { position, orientation | lookAt, fovDeg }');
  const position = spec.position ?? current.position;
  if (!finite3(position)) throw new Error('position must be 3 finite numbers [x, y, z]');
  const fovDeg = spec.fovDeg ?? current.fovDeg;
  if (!(fovDeg > 1 && fovDeg < 170)) throw new Error('fovDeg must be in (1, 170)');
  if (spec.lookAt !== undefined) {
    const target = spec.lookAt;
    const up = spec.up ?? current.up;
    if (!finite3(target)) throw new Error('lookAt must be 3 finite numbers [x, y, z]');
    if (!finite3(up) || !(vlen(up) > 0)) throw new Error('up must be 3 finite numbers, not all 0');
    if (!(vlen(vsub(target, position)) > 0)) throw new Error('lookAt must differ from position');
    return { position: position.slice(), orientation: lookAt(position, target, up), fovDeg, target: target.slice() };
  }
  const orientation = spec.orientation ?? spec.rotation ?? current.orientation;
  if (!finite4(orientation)) throw new Error('orientation must be 4 finite numbers [w, x, y, z]');
  return { position: position.slice(), orientation: orientation.slice(), fovDeg, target: null };
}

// A path for playPath as { duration (s), at(t) -> pose, keys (the waypoints, or null) }:
//   - an array of timed samples ({ t (s), position, orientation, fovDeg }: a recording, a .trace
//     file read) plays on its own clock, interpolated between samples (paths.js poseAtTime);
//   - an array of waypoints (no `t`) plays as a tour, `secondsPerView` apart, with the core's
//     interpolation (paths.js tourPoseAt: centripetal Catmull-Rom and slerp);
//   - a string: a cameras.json (its views: a tour) or a catgs-trace file (timed).
// Each pose or waypoint is what setPose takes (resolvePose: lookAt too), what it leaves out as in
// `current` (the camera now); other fields (a waypoint's `hotspot`) stay. Throws for anything
// else, and for a tour of fewer than 2 views.
export function playbackOf(path, secondsPerView, current) {
  if (typeof path === 'string') path = /^\s*\[/.test(path) ? fromInriaCameras(path) : fromTraceFile(path);
  if (!Array.isArray(path) || !path.length) throw new Error('a path is an array of poses or timed samples, or a file\'s text');
  path = path.map((p) => {
    const r = resolvePose(p, current);
    return { ...p, position: r.position, orientation: r.orientation, fovDeg: r.fovDeg };
  });
  if (path.every((p) => Number.isFinite(p.t))) {
    return { duration: path[path.length - 1].t, at: (t) => poseAtTime(path, t), keys: null };
  }
  if (path.length < 2) throw new Error('a tour needs at least 2 views');
  if (!(secondsPerView > 0)) throw new Error('secondsPerView must be above 0');
  return { duration: tourDuration(path, secondsPerView), at: (t) => tourPoseAt(path, t, secondsPerView), keys: path };
}
