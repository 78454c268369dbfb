// The depth warp (issue 91): the frame re-projected to the visitor's newer pose by its depth grid
// (Frame.depth_grid, proto/catgs_stream.proto DepthGrid) as a mesh, so that a step sideways shows
// parallax where the plane homography (reproject.js) moves the whole picture as one plane. Pure
// (no DOM, no WebGL), so node can unit-test it; warp_gl.js draws the mesh. The C++ twin,
// tools/shown/depth_warp.h (what catgs-shown scores), is tested equal to warpVertices under node
// (tests/unit/page_reprojection_test.cpp).
//
// The mesh: vertex (k, l) at image point (x, y) = (min(k cell, width), min(l cell, height)) of the
// frame with inverse depth w (a vertex with no surface takes the page's plane: an object in empty
// space lies between such vertices, and at infinity its pixels would move as the background does).
// It is the homogeneous point (r, w) of the frame's camera, r = K1^-1 (x, y, 1), i.e. X1 = r / w;
// in the new camera X2h = R r + t w, with R = W2 W1^T and t = W2 (p1 - p2) as reprojection()'s.
// Its image is K2 X2h / X2h.z; 1 / z2 = w / X2h.z. Drawn with clip w = X2h.z, the GPU's
// perspective-correct interpolation of the frame's coordinates is the exact image-to-image map of
// a planar patch between the vertices, and a depth test on 1 / z2 lets the nearest surface win
// where the warp folds. Across a depth edge the triangles stretch over what the frame did not see
// (a rubber sheet): the frame's nearest pixels, never black. A triangle with a vertex at or
// behind the new camera (X2h.z <= 1e-9) is not drawn.
// Conventions as camera.js: OpenCV axes (x right, y down, z forward), orientation camera-to-world.

import { intrinsicsFor, qrotate, vdot, vsub } from './camera.js';

const MAX_SIDE = 4097;

// The grid a Frame carries, its codes inflated (`codes`: the cols x rows bytes) -> { cols, rows,
// cell, depth: Float64Array (world units, Infinity where code 0: no surface) }, by
// proto/depth_grid_coding.h's rule: code c in 1..255 is inverse depth c / 255 * inverse_depth_max.
// Throws on a malformed grid (its shape, its codes' length, its scale).
export function depthGridOf(g, codes) {
  const cols = g.cols >>> 0;
  const rows = g.rows >>> 0;
  const cell = g.cell_px >>> 0;
  if (!(cols >= 1 && rows >= 1 && cols <= MAX_SIDE && rows <= MAX_SIDE)) throw new Error(`depth grid: shape ${cols} x ${rows}`);
  if (!(cell >= 1)) throw new Error('depth grid: cell_px is 0');
  if (codes.length !== cols * rows) throw new Error(`depth grid: ${codes.length} codes for ${cols} x ${rows} vertices`);
  const wMax = Math.fround(g.inverse_depth_max);
  const depth = new Float64Array(cols * rows).fill(Infinity);
  for (let i = 0; i < depth.length; i++) {
    if (codes[i] === 0) continue;
    if (!(Number.isFinite(wMax) && wMax > 0)) throw new Error(`depth grid: inverse_depth_max ${wMax}`);
    depth[i] = Math.fround(255 / Math.fround(codes[i] * wMax));
  }
  return { cols, rows, cell, depth };
}

// Inflates Frame.depth_grid's codes (zlib, RFC 1950: DecompressionStream('deflate')) and reads
// the grid (depthGridOf). Resolves null for a frame without one; rejects on a malformed one.
export async function inflateDepthGrid(g) {
  if (!g || !g.cols) return null;
  const stream = new Blob([g.inverse_depth]).stream().pipeThrough(new DecompressionStream('deflate'));
  const codes = new Uint8Array(await new Response(stream).arrayBuffer());
  return depthGridOf(g, codes);
}

// World -> camera rotation rows of a camera-to-world quaternion (reproject.js worldToCamera).
function worldToCamera(q) {
  return [qrotate(q, [1, 0, 0]), qrotate(q, [0, 1, 0]), qrotate(q, [0, 0, 1])];
}

// The mesh's vertices as pose `to` sees them, for a width x height frame of pose `from` and its
// grid: { sx, sy (image point in `to`, pixels; 0 where behind), clipW (X2h.z), invZ (1 / z2),
// u, v (the frame's image point) }, each a Float64Array of cols x rows, row-major.
export function warpVertices(from, to, grid, planeDepth, width, height) {
  const k1 = intrinsicsFor(from.fovDeg, width, height);
  const k2 = intrinsicsFor(to.fovDeg, width, height);
  const w1 = worldToCamera(from.orientation);
  const w2 = worldToCamera(to.orientation);
  // R = W2 W1^T: R[i][j] = row i of W2 . row j of W1.
  const R = w2.map((a) => w1.map((b) => vdot(a, b)));
  const d = vsub(from.position, to.position);
  const t = w2.map((a) => vdot(a, d));
  const n = grid.cols * grid.rows;
  const out = {
    sx: new Float64Array(n),
    sy: new Float64Array(n),
    clipW: new Float64Array(n),
    invZ: new Float64Array(n),
    u: new Float64Array(n),
    v: new Float64Array(n),
  };
  for (let l = 0; l < grid.rows; l++) {
    for (let k = 0; k < grid.cols; k++) {
      const i = l * grid.cols + k;
      const x = Math.min(k * grid.cell, width);
      const y = Math.min(l * grid.cell, height);
      const z = grid.depth[i];
      const inv = Number.isFinite(z) && z > 0 ? 1 / z : 1 / planeDepth;
      const r = [(x - k1.cx) / k1.fx, (y - k1.cy) / k1.fy, 1];
      const X = [0, 1, 2].map((a) => R[a][0] * r[0] + R[a][1] * r[1] + R[a][2] * r[2] + t[a] * inv);
      out.u[i] = x;
      out.v[i] = y;
      out.clipW[i] = X[2];
      if (X[2] > 1e-9) {
        out.sx[i] = (k2.fx * X[0]) / X[2] + k2.cx;
        out.sy[i] = (k2.fy * X[1]) / X[2] + k2.cy;
        out.invZ[i] = inv / X[2];
      }
    }
  }
  return out;
}

// The triangles to draw (vertex indices, three a triangle): two a cell, (a, b, d) and (a, d, c)
// with a top-left, b top-right, c bottom-left, d bottom-right, each only where all three of its
// vertices are in front of the new camera.
export function warpTriangles(grid, verts) {
  const out = [];
  const front = (i) => verts.clipW[i] > 1e-9;
  for (let l = 0; l + 1 < grid.rows; l++) {
    for (let k = 0; k + 1 < grid.cols; k++) {
      const a = l * grid.cols + k;
      const b = a + 1;
      const c = a + grid.cols;
      const d = c + 1;
      if (front(a) && front(b) && front(d)) out.push(a, b, d);
      if (front(a) && front(d) && front(c)) out.push(a, d, c);
    }
  }
  return Uint32Array.from(out);
}

// The scene's depth (world units along the frame's forward axis) under image point (x, y) of the
// frame, bilinear between the four vertices around it; null where one of them that counts has no
// surface.
export function depthAt(grid, width, height, x, y) {
  const fx = Math.min(Math.max(x, 0), width) / grid.cell;
  const fy = Math.min(Math.max(y, 0), height) / grid.cell;
  const k = Math.min(Math.floor(fx), grid.cols - 2);
  const l = Math.min(Math.floor(fy), grid.rows - 2);
  if (k < 0 || l < 0) return null;
  // The last cell may be narrower (the edge vertex sits at the image's edge).
  const x0 = k * grid.cell;
  const x1 = Math.min((k + 1) * grid.cell, width);
  const y0 = l * grid.cell;
  const y1 = Math.min((l + 1) * grid.cell, height);
  const a = (Math.min(Math.max(x, x0), x1) - x0) / Math.max(x1 - x0, 1e-9);
  const b = (Math.min(Math.max(y, y0), y1) - y0) / Math.max(y1 - y0, 1e-9);
  const at = (dk, dl) => grid.depth[(l + dl) * grid.cols + (k + dk)];
  const z = [at(0, 0), at(1, 0), at(0, 1), at(1, 1)];
  const weight = [(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b];
  // Bilinear in inverse depth (what is linear across a planar patch's image), then back; a vertex
  // with no surface that carries weight leaves the point without a depth.
  let w = 0;
  for (let i = 0; i < 4; i++) {
    if (weight[i] === 0) continue;
    if (!Number.isFinite(z[i])) return null;
    w += weight[i] / z[i];
  }
  return 1 / w;
}
