#include "shown/depth_warp.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include "forward_model/depth_grid.h"

namespace catgs::shown {

namespace {

using Vertex = WarpVertex;

double edge(double ax, double ay, double bx, double by, double px, double py) {
  return (bx - ax) * (py - ay) - (by - ay) * (px - ax);
}

// Draws triangle (a, b, c) into out with the depth test over `nearest` (1 / z2 a pixel).
void draw_triangle(const Vertex& a, const Vertex& b, const Vertex& c, const Image& frame, Image& out,
                   std::vector<double>& nearest) {
  const double area = edge(a.sx, a.sy, b.sx, b.sy, c.sx, c.sy);
  if (!(std::abs(area) > 1e-12)) return;
  const int w = out.width, h = out.height;
  const int i0 = std::max(0, static_cast<int>(std::floor(std::min({a.sx, b.sx, c.sx}) - 0.5)));
  const int i1 = std::min(w - 1, static_cast<int>(std::ceil(std::max({a.sx, b.sx, c.sx}) - 0.5)));
  const int j0 = std::max(0, static_cast<int>(std::floor(std::min({a.sy, b.sy, c.sy}) - 0.5)));
  const int j1 = std::min(h - 1, static_cast<int>(std::ceil(std::max({a.sy, b.sy, c.sy}) - 0.5)));
  for (int j = j0; j <= j1; ++j)
    for (int i = i0; i <= i1; ++i) {
      const double px = i + 0.5, py = j + 0.5;
      // Screen barycentrics; a pixel centre on a shared edge is drawn by both (the depth test
      // picks one, the colours agree there).
      const double ba = edge(b.sx, b.sy, c.sx, c.sy, px, py) / area;
      const double bb = edge(c.sx, c.sy, a.sx, a.sy, px, py) / area;
      const double bc = 1.0 - ba - bb;
      if (ba < -1e-9 || bb < -1e-9 || bc < -1e-9) continue;
      const double inv_z = ba * a.inv_z + bb * b.inv_z + bc * c.inv_z;
      const std::size_t p = static_cast<std::size_t>(j) * w + i;
      if (!(inv_z > nearest[p])) continue;
      nearest[p] = inv_z;
      const double wa = ba / a.clip_w, wb = bb / b.clip_w, wc = bc / c.clip_w, sum = wa + wb + wc;
      const double u = (wa * a.u + wb * b.u + wc * c.u) / sum, v = (wa * a.v + wb * b.v + wc * c.v) / sum;
      const auto rgb = sample_bilinear(frame, u, v);
      std::uint8_t* o = &out.rgba8[p * 4];
      for (int ch = 0; ch < 3; ++ch)
        o[ch] = static_cast<std::uint8_t>(std::lround(std::clamp(rgb[static_cast<std::size_t>(ch)], 0.0, 255.0)));
    }
}

}  // namespace

std::vector<WarpVertex> warp_vertices(const PagePose& from, const PagePose& to, const DepthGrid& grid,
                                      double plane_depth, int w, int h) {
  if (grid.cell < 1 || grid.cols != fm::depth_grid_cols(w, grid.cell) ||
      grid.rows != fm::depth_grid_rows(h, grid.cell) ||
      grid.depth.size() != static_cast<std::size_t>(grid.cols) * grid.rows)
    throw std::invalid_argument("depth warp: a " + std::to_string(grid.cols) + " x " + std::to_string(grid.rows) +
                                " grid of cell " + std::to_string(grid.cell) + " does not fit a " + std::to_string(w) +
                                " x " + std::to_string(h) + " frame");
  const Intrinsics k1 = intrinsics_for(from.fov_deg, w, h), k2 = intrinsics_for(to.fov_deg, w, h);
  // R = W2 W1^T, t = W2 (p1 - p2) (reproject.js reprojection's), W the world-to-camera rotations.
  const glm::dmat3 c2w1 = glm::mat3_cast(from.orientation), c2w2 = glm::mat3_cast(to.orientation);
  const glm::dmat3 R = glm::transpose(c2w2) * c2w1;
  const glm::dvec3 t = glm::transpose(c2w2) * (from.position - to.position);
  std::vector<Vertex> verts(grid.depth.size());
  for (int l = 0; l < grid.rows; ++l)
    for (int k = 0; k < grid.cols; ++k) {
      const double x = std::min(k * grid.cell, w), y = std::min(l * grid.cell, h);
      const float z = grid.depth[static_cast<std::size_t>(l) * grid.cols + k];
      const double inv = std::isfinite(z) && z > 0.0f ? 1.0 / z : 1.0 / plane_depth;
      const glm::dvec3 r((x - k1.cx) / k1.fx, (y - k1.cy) / k1.fy, 1.0);
      const glm::dvec3 X = R * r + t * inv;
      Vertex& v = verts[static_cast<std::size_t>(l) * grid.cols + k];
      v.u = x;
      v.v = y;
      v.clip_w = X.z;
      if (X.z > 1e-9) {
        v.sx = k2.fx * X.x / X.z + k2.cx;
        v.sy = k2.fy * X.y / X.z + k2.cy;
        v.inv_z = inv / X.z;
      }
    }
  return verts;
}

Image depth_warp_picture(const Image& frame, const PagePose& from, const PagePose& to, const DepthGrid& grid,
                         double plane_depth) {
  Image out = shown_picture(frame, from, to, plane_depth);  // checks the frame; the backdrop
  if (grid.cols == 0 || same_pose(from, to)) return out;
  const int w = frame.width, h = frame.height;
  const std::vector<Vertex> verts = warp_vertices(from, to, grid, plane_depth, w, h);
  std::vector<double> nearest(static_cast<std::size_t>(w) * h, -std::numeric_limits<double>::infinity());
  for (int l = 0; l + 1 < grid.rows; ++l)
    for (int k = 0; k + 1 < grid.cols; ++k) {
      const auto at = [&](int dk, int dl) -> const Vertex& {
        return verts[static_cast<std::size_t>(l + dl) * grid.cols + (k + dk)];
      };
      const Vertex &a = at(0, 0), &b = at(1, 0), &c = at(0, 1), &d = at(1, 1);
      if (a.clip_w > 1e-9 && b.clip_w > 1e-9 && d.clip_w > 1e-9) draw_triangle(a, b, d, frame, out, nearest);
      if (a.clip_w > 1e-9 && d.clip_w > 1e-9 && c.clip_w > 1e-9) draw_triangle(a, d, c, frame, out, nearest);
    }
  return out;
}

}  // namespace catgs::shown
