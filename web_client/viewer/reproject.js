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
  return reprojectionK(from, to, planeDepth, intrinsicsFor(from.fovDeg, width, height), intrinsicsFor(to.fovDeg, width, height));
}

// reprojection() for any two pinhole cameras: `k1`, `k2` { fx, fy, cx, cy } the intrinsics of the
// images of `from` and `to` ({ position, orientation }), which may differ in size and may be
// asymmetric (a headset's eye: stereo.js eyeIntrinsics), so a VR eye's frame goes to where the
// eye looks now (xr.js).
export function reprojectionK(from, to, planeDepth, k1, k2) {
  const w2 = worldToCamera(to.orientation);
  // R = W2 W1^T (its columns: the first camera's axes seen from the second); t = W2 (p1 - p2).
  const q1 = from.orientation;
  const axes1 = [qrotate(q1, [1, 0, 0]), qrotate(q1, [0, 1, 0]), cameraForward(q1)];
  const cols = axes1.map((a) => matVec(w2, a));
  const R = [0, 1, 2].map((i) => [cols[0][i], cols[1][i], cols[2][i]]);
  const t = matVec(w2, vsub(from.position, to.position));
  // A = R + t n^T / d with n = (0, 0, 1): only the third column changes.
  const A = R.map((row, i) => [row[0], row[1], row[2] + t[i] / planeDepth]);
  // H = K2 A K1^-1, K1^-1 = [[1/fx, 0, -cx/fx], [0, 1/fy, -cy/fy], [0, 0, 1]].
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

// The inverse of a 3x3 matrix (rows); null when singular.
export function invert3(m) {
  const [[a, b, c], [d, e, f], [g, h, i]] = m;
  const A = e * i - f * h;
  const B = f * g - d * i;
  const C = d * h - e * g;
  const det = a * A + b * B + c * C;
  if (!(Math.abs(det) > 1e-300)) return null;
  const s = 1 / det;
  return [
    [A * s, (c * h - b * i) * s, (b * f - c * e) * s],
    [B * s, (a * i - c * g) * s, (c * d - a * f) * s],
    [C * s, (b * g - a * h) * s, (a * e - b * d) * s],
  ];
}

// What fills the view around the re-projected frame, where it does not reach (a turn or a pan
// uncovers an edge, a zoom-out all four): the frame's edge, continued (clamp-to-edge), so that the
// uncovered part goes on from the frame's nearest edge instead of showing black. Each view pixel
// outside the frame's outline on screen (a convex quadrilateral: H of the frame's corners) takes
// the colour of the outline's nearest point; inside, the frame's own pixel (the canvas covers
// those; they keep the stretched edge smooth). Clamped on screen rather than in the frame's
// coordinates, which near the horizon of a large turn's plane run off to a corner's colour, and
// past it have none. `src` and `out` are RGBA pixels ({ data, width, height }, ImageData-like) of
// the frame and of the view, both at a small size (app.js: at most 256 pixels across); H is the
// re-projection of a width x height frame (reprojection()); out covers the same width x height.
// Returns false (out untouched) when the frame's outline is not all in front (no transform then).
export function edgeFill(H, width, height, src, out) {
  const Hi = invert3(H);
  const quad = [[0, 0], [width, 0], [width, height], [0, height]].map(([x, y]) => applyHomography(H, x, y));
  if (!Hi || quad.some((q) => q === null)) return false;
  // The outline's edges, and which side of them is inside (the quad's orientation).
  const edges = quad.map((a, k) => {
    const b = quad[(k + 1) % 4];
    const d = [b[0] - a[0], b[1] - a[1]];
    return { a, d, len2: d[0] * d[0] + d[1] * d[1] };
  });
  const area = edges.reduce((acc, e) => acc + e.a[0] * (e.a[1] + e.d[1]) - (e.a[0] + e.d[0]) * e.a[1], 0);
  const sign = area >= 0 ? 1 : -1;
  const sx = src.width / width;
  const sy = src.height / height;
  const ox = width / out.width;
  const oy = height / out.height;
  const sd = src.data;
  const od = out.data;
  for (let j = 0; j < out.height; j++) {
    for (let i = 0; i < out.width; i++) {
      let x = (i + 0.5) * ox;
      let y = (j + 0.5) * oy;
      if (edges.some((e) => sign * (e.d[0] * (y - e.a[1]) - e.d[1] * (x - e.a[0])) < 0)) {
        // Outside: the nearest point of the outline.
        let best = Infinity;
        let nx = x;
        let ny = y;
        for (const e of edges) {
          const t = e.len2 > 0 ? Math.min(Math.max(((x - e.a[0]) * e.d[0] + (y - e.a[1]) * e.d[1]) / e.len2, 0), 1) : 0;
          const px = e.a[0] + t * e.d[0];
          const py = e.a[1] + t * e.d[1];
          const dist2 = (px - x) * (px - x) + (py - y) * (py - y);
          if (dist2 < best) {
            best = dist2;
            nx = px;
            ny = py;
          }
        }
        x = nx;
        y = ny;
      }
      const W = Hi[2][0] * x + Hi[2][1] * y + Hi[2][2];
      const u = (Hi[0][0] * x + Hi[0][1] * y + Hi[0][2]) / W;
      const v = (Hi[1][0] * x + Hi[1][1] * y + Hi[1][2]) / W;
      const si = Math.min(Math.max(Math.floor(u * sx), 0), src.width - 1) || 0;
      const sj = Math.min(Math.max(Math.floor(v * sy), 0), src.height - 1) || 0;
      const s = (sj * src.width + si) * 4;
      const o = (j * out.width + i) * 4;
      od[o] = sd[s];
      od[o + 1] = sd[s + 1];
      od[o + 2] = sd[s + 2];
      od[o + 3] = 255;
    }
  }
  return true;
}
