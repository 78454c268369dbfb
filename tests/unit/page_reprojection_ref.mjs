// The page's own re-projection (web_client/viewer/reproject.js) run on a job from
// page_reprojection_test.cpp, so the C++ twin (tools/shown/page_reprojection.h) is compared with
// the code the visitor's browser runs, not with a second reading of it.
//   node page_reprojection_ref.mjs JOB.json   (or the job on stdin)
// Job (JSON; poses as the page holds them: { position: [x, y, z], orientation: [w, x, y, z],
// fovDeg }):
//   reprojections: [{ from, to, planeDepth, width, height }]
//   depths:        [{ pose, target: [x, y, z], fallback }]
//   edgeFills:     [{ from, to, planeDepth, width, height, H, src, out }]  (src, out:
//                  { width, height, data: [RGBA bytes] }; H: the C++ twin's homography)
//   warps:         [{ from, to, planeDepth, width, height, grid: { cols, rows, cell, depth:
//                  [number or null for no surface] } }]  (web_client/viewer/depth_warp.js)
// Prints (stdout, JSON):
//   reprojections: [{ H, corners: [[x, y] or null for (0,0), (w,0), (w,h), (0,h)], inverse }]
//   depths:        [number]
//   edgeFills:     [{ ok, data, okOwnH, dataOwnH }]  (edgeFill with the given H, and with the
//                  page's own reprojection() of the case's poses)
//   warps:         [{ sx, sy, clipW, invZ, u, v, triangles }]  (warpVertices, warpTriangles)
import { readFileSync } from 'node:fs';

const { applyHomography, edgeFill, invert3, planeDepthFor, reprojection } = await import(
  new URL('../../web_client/viewer/reproject.js', import.meta.url).href
);

const { warpTriangles, warpVertices } = await import(new URL('../../web_client/viewer/depth_warp.js', import.meta.url).href);

const text = process.argv[2] ? readFileSync(process.argv[2], 'utf8') : readFileSync(0, 'utf8');
const job = JSON.parse(text);

const corners = (H, w, h) => [[0, 0], [w, 0], [w, h], [0, h]].map(([x, y]) => applyHomography(H, x, y));

const image = (img) => ({ width: img.width, height: img.height, data: Uint8ClampedArray.from(img.data) });

function fill(H, c) {
  const out = image(c.out);
  const ok = edgeFill(H, c.width, c.height, image(c.src), out);
  return { ok, data: Array.from(out.data) };
}

const result = {
  reprojections: (job.reprojections || []).map((c) => {
    const H = reprojection(c.from, c.to, c.planeDepth, c.width, c.height);
    return { H, corners: corners(H, c.width, c.height), inverse: invert3(H) };
  }),
  depths: (job.depths || []).map((c) => planeDepthFor(c.pose, c.target, c.fallback)),
  edgeFills: (job.edgeFills || []).map((c) => {
    const given = fill(c.H, c);
    const own = fill(reprojection(c.from, c.to, c.planeDepth, c.width, c.height), c);
    return { ok: given.ok, data: given.data, okOwnH: own.ok, dataOwnH: own.data };
  }),
  warps: (job.warps || []).map((c) => {
    const grid = { ...c.grid, depth: Float64Array.from(c.grid.depth, (z) => (z === null ? Infinity : z)) };
    const v = warpVertices(c.from, c.to, grid, c.planeDepth, c.width, c.height);
    const out = Object.fromEntries(Object.entries(v).map(([k, a]) => [k, Array.from(a)]));
    return { ...out, triangles: Array.from(warpTriangles(grid, v)) };
  }),
};
process.stdout.write(JSON.stringify(result));
