// Latency hiding: while the frame for the newest pose is on its way, the page shows the last
// frame re-projected to that pose, so a drag moves the picture at once. Pure (no DOM), so node can
// unit-test it.
//
// The re-projection is the homography that a plane induces between two pinhole views (Hartley &
// Zisserman, "Multiple View Geometry", 2nd ed., sec. 13.1): for a plane n . X = d in the first
// camera's coordinates, x2 ~ K (R + t n^T / d) K^-1 x1, with X2 = R X1 + t taking first-camera
// coordinates to second-camera ones. The plane is the one facing the first camera through the
// orbit target (what the viewer looks at), so content at the target's depth lands exactly and
// nearer or farther content approximately; a pure rotation is exact at every depth.
// Conventions as camera.js: OpenCV axes (x right, y down, z forward), orientation camera-to-world.

import { intrinsicsFor, qrotate, vdot, vsub, cameraForward } from './camera.js';

// World -> camera rotation of a camera-to-world quaternion, as rows of a 3x3 matrix.
function worldToCamera(q) {
  const r = qrotate(q, [1, 0, 0]);
  const d = qrotate(q, [0, 1, 0]);
  const f = qrotate(q, [0, 0, 1]);
  return [r, d, f];
}

const matVec = (m, v) => [vdot(m[0], v), vdot(m[1], v), vdot(m[2], v)];

// The 3x3 homography (rows) taking pixels of an image rendered at pose `from` to where the same
// plane points appear at pose `to`; both poses { position, orientation, fovDeg } at width x height
// pixels; `planeDepth` the plane's distance along `from`'s forward axis (world units, > 0).
export function reprojection(from, to, planeDepth, width, height) {
  const k1 = intrinsicsFor(from.fovDeg, width, height);
  const k2 = intrinsicsFor(to.fovDeg, width, height);
  const w2 = worldToCamera(to.orientation);
  // R = W2 W1^T (its columns: the first camera's axes seen from the second); t = W2 (p1 - p2).
  const q1 = from.orientation;
  const axes1 = [qrotate(q1, [1, 0, 0]), qrotate(q1, [0, 1, 0]), cameraForward(q1)];
  const cols = axes1.map((a) => matVec(w2, a));
  const R = [0, 1, 2].map((i) => [cols[0][i], cols[1][i], cols[2][i]]);
  const t = matVec(w2, vsub(from.position, to.position));
  // A = R + t n^T / d with n = (0, 0, 1): only the third column changes.
  const A = R.map((row, i) => [row[0], row[1], row[2] + t[i] / planeDepth]);
  // H = K2 A K1^-1, K1^-1 = [[1/f, 0, -cx/f], [0, 1/f, -cy/f], [0, 0, 1]].
  const kInv = [
    [1 / k1.fx, 0, -k1.cx / k1.fx],
    [0, 1 / k1.fy, -k1.cy / k1.fy],
    [0, 0, 1],
  ];
  const K2 = [
    [k2.fx, 0, k2.cx],
    [0, k2.fy, k2.cy],
    [0, 0, 1],
  ];
  const mul = (a, b) => a.map((row) => [0, 1, 2].map((j) => row[0] * b[0][j] + row[1] * b[1][j] + row[2] * b[2][j]));
  return mul(mul(K2, A), kInv);
}

// Applies a homography to pixel (x, y); null behind the camera.
export function applyHomography(H, x, y) {
  const w = H[2][0] * x + H[2][1] * y + H[2][2];
  if (!(w > 1e-9)) return null;
  return [(H[0][0] * x + H[0][1] * y + H[0][2]) / w, (H[1][0] * x + H[1][1] * y + H[1][2]) / w];
}

// The plane depth for a view: the orbit target's distance along the frame's forward axis, or, when
// the target is behind or nearly at the camera, `fallback` (a rotation then dominates anyway).
export function planeDepthFor(pose, target, fallback) {
  const d = vdot(vsub(target, pose.position), cameraForward(pose.orientation));
  return d > 1e-6 ? d : fallback;
}

// A CSS transform (transform-origin 0 0) that shows a canvas holding an image of width x height
// pixels, stretched to cssWidth x cssHeight, re-projected by H: S H S^-1 with S the stretch,
// written as matrix3d (column-major).
export function cssTransform(H, width, height, cssWidth, cssHeight) {
  const sx = cssWidth / width;
  const sy = cssHeight / height;
  const m = [
    [H[0][0], H[0][1] * (sx / sy), H[0][2] * sx],
    [H[1][0] * (sy / sx), H[1][1], H[1][2] * sy],
    [H[2][0] / sx, H[2][1] / sy, H[2][2]],
  ];
  const s = m[2][2];
  const v = (a) => Number((a / s).toPrecision(9));
  return `matrix3d(${v(m[0][0])},${v(m[1][0])},0,${v(m[2][0])},${v(m[0][1])},${v(m[1][1])},0,${v(m[2][1])},0,0,1,0,${v(
    m[0][2],
  )},${v(m[1][2])},0,${v(m[2][2])})`;
}
