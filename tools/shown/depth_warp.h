// The depth warp (issue 91, "Depth with every frame"): the last frame re-projected to the
// visitor's newer pose by its depth grid (Frame.depth_grid, proto/depth_grid_coding.h) as a mesh,
// so that a step sideways shows parallax, where the page's plane homography (page_reprojection.h)
// moves the whole picture as one plane.
//
// The mesh: the grid's vertices (k, l) at image points (x_k, y_l) of the frame (pixel i covers
// [i, i + 1)) with inverse depth w, two triangles a cell
// (the diagonal from top-left to bottom-right). A vertex is the homogeneous point (r, w) of the
// frame's camera, r = K1^-1 (x, y, 1) its ray (r.z = 1), i.e. X1 = r / w; in the new camera
// X2h = R r + t w (= X2 / z1, finite for the background too: a direction). Its image is
// K2 X2h / X2h.z and 1 / z2 = w / X2h.z. Each triangle is rasterised at the output's pixel
// centres with texture coordinates interpolated perspective-correctly with clip w = X2h.z (for a
// planar patch between the vertices this is the exact image-to-image map: the weights are
// z1 / z2), and a depth test on 1 / z2 (the nearest surface wins where the warp folds). Where a
// step uncovers what the frame did not see, the triangles between a near and a far vertex stretch
// across the gap (a rubber sheet), so the hole shows the frame's nearest pixels, never black.
// A vertex with no surface (the background) takes the page's plane (`plane_depth`), not infinity:
// an object in empty space (the biker) is drawn between such vertices at a 32-pixel grid, and at
// infinity its pixels would move as the background does (docs/history/shown_picture.md).
// A triangle with a vertex at or behind the new camera (X2h.z <= 1e-9) is not drawn. Pixels no
// triangle covers (past the frame's moved edge) show what the page shows there today:
// shown_picture() with the plane at `plane_depth`.
//
// The page draws the same mesh with WebGL2 (web_client/viewer/depth_warp.js, warp_gl.js: the frame
// as a texture with linear filtering and clamp to edge, clip w, the depth test); warp_vertices is
// tested equal to its warpVertices under node. The rasterisation is modelled as a GPU does it
// (pixel centres, bilinear samples), close, not byte-exact, as shown_picture's browser.
#pragma once

#include <vector>

#include "renderer/renderer.h"
#include "shown/page_reprojection.h"

namespace catgs::shown {

// A mesh vertex as the new camera sees it (the page's depth_warp.js warpVertices: sx, sy, clipW,
// invZ, u, v).
struct WarpVertex {
  double sx = 0, sy = 0;  // image point in the new camera, pixels (0 where behind)
  double clip_w = 0;      // X2h.z: > 0 in front
  double inv_z = 0;       // 1 / z2, world units^-1 (0 where behind)
  double u = 0, v = 0;    // the frame's image point it carries
};

// The mesh's vertices, cols x rows row-major, for a width x height frame of `from` and its grid as
// `to` sees them; vertices with no surface at `plane_depth`. Throws std::invalid_argument for a
// grid whose shape is not depth_grid_cols/rows of the frame's size at its cell.
std::vector<WarpVertex> warp_vertices(const PagePose& from, const PagePose& to, const DepthGrid& grid,
                                      double plane_depth, int width, int height);

// `frame` (RGBA8) rendered at `from`, with its depth grid `grid` (renderer.h DepthGrid: depths in
// world units, +inf for the background; its cell in the frame's pixels), as seen from `to`, at
// the frame's size. The plain frame when the poses are the same; shown_picture() where the grid
// is empty. Throws std::invalid_argument for an empty frame, or a grid whose shape is not
// depth_grid_cols/rows of the frame's size at its cell.
Image depth_warp_picture(const Image& frame, const PagePose& from, const PagePose& to, const DepthGrid& grid,
                         double plane_depth);

}  // namespace catgs::shown
