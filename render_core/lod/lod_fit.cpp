// Fitting a merged Gaussian to what its children draw (lod_fit.h).
#include "lod/lod_fit.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

#include "forward_model/forward_model.h"

namespace catgs {

namespace {

constexpr int kGrid = 12;        // grid points a side
constexpr double kExtent = 3.5;  // the grid's half-width, merged std devs
constexpr double kTwoPi = 6.283185307179586;

// The view directions in the merged Gaussian's frame (lod_fit.h).
constexpr double kD = 0.5773502691896258;  // 1 / sqrt(3)
constexpr double kDirections[7][3] = {{1, 0, 0},     {0, 1, 0},     {0, 0, 1},    {kD, kD, kD},
                                      {-kD, kD, kD}, {kD, -kD, kD}, {kD, kD, -kD}};

// An orthonormal basis (u, v) of the plane perpendicular to unit `d`.
void plane_basis(const glm::dvec3& d, glm::dvec3& u, glm::dvec3& v) {
  const glm::dvec3 helper = std::fabs(d.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
  u = glm::normalize(glm::cross(d, helper));
  v = glm::cross(d, u);
}

// One child projected along a direction: its mean on the plane, its conic (widened for the
// grid), its peak, and its depth along the direction.
struct Splat2 {
  double x, y;
  double a, b, c;  // q = a dx^2 + 2 b dx dy + c dy^2
  double peak;
  double q_cut;  // peak exp(-q / 2) < 1/255 beyond it: 2 ln(255 peak) (opacity_aware_qmax)
  double depth;
};

}  // namespace

LodFit fit_to_children(const LodFitChild* children, int count, const glm::dvec3& mean, const glm::dmat3& cov,
                       const glm::dmat3& axes) {
  if (count < 1) throw std::invalid_argument("fit_to_children: no children");
  const std::size_t n = static_cast<std::size_t>(count);
  LodFit fit;
  fit.colour_weight.assign(n, 0.0);
  std::vector<Splat2> s(n);
  std::vector<double> alpha(n);
  std::vector<int> order(n);
  double covered = 0.0, merged_area = 0.0;  // sums over the directions
  for (const auto& local : kDirections) {
    const glm::dvec3 d = glm::normalize(axes * glm::dvec3(local[0], local[1], local[2]));
    glm::dvec3 u, v;
    plane_basis(d, u, v);
    const auto project = [&](const glm::dmat3& c, double& xx, double& xy, double& yy) {
      const glm::dvec3 cu = c * u, cv = c * v;
      xx = glm::dot(u, cu), xy = glm::dot(u, cv), yy = glm::dot(v, cv);
    };
    double mxx, mxy, myy;
    project(cov, mxx, mxy, myy);
    const double det_m = mxx * myy - mxy * mxy;
    if (!(det_m > 0.0)) continue;
    // The grid: a square over +-kExtent std devs of the merged projection's long axis.
    const double half = 0.5 * (mxx + myy), largest = half + std::sqrt(std::max(0.0, half * half - det_m));
    const double ext = kExtent * std::sqrt(largest), step = 2.0 * ext / kGrid, widen = 0.25 * step * step;
    for (std::size_t i = 0; i < n; ++i) {
      double xx, xy, yy;
      project(children[i].cov, xx, xy, yy);
      const double det0 = std::max(xx * yy - xy * xy, 0.0);
      xx += widen, yy += widen;
      const double det = xx * yy - xy * xy;
      const glm::dvec3 r = children[i].mean - mean;
      const double peak = children[i].alpha * std::sqrt(det0 / det);
      s[i] = {glm::dot(r, u),
              glm::dot(r, v),
              yy / det,
              -xy / det,
              xx / det,
              peak,
              peak > 0.0 ? 2.0 * std::log(255.0 * peak) : -1.0,
              glm::dot(r, d)};
    }
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](int x, int y) { return s[x].depth < s[y].depth; });
    double sum = 0.0;
    for (int gy = 0; gy < kGrid; ++gy)
      for (int gx = 0; gx < kGrid; ++gx) {
        const double px = -ext + (gx + 0.5) * step, py = -ext + (gy + 0.5) * step;
        double t = 1.0;
        for (std::size_t i = 0; i < n; ++i) {
          const double dx = px - s[i].x, dy = py - s[i].y;
          const double q = s[i].a * dx * dx + 2.0 * s[i].b * dx * dy + s[i].c * dy * dy;
          // Below 1/255 the rasterizer skips it; the test on q first spares most exps.
          const double a =
              q > s[i].q_cut ? 0.0 : std::min(static_cast<double>(fm::kMaxAlpha), s[i].peak * std::exp(-0.5 * q));
          alpha[i] = a >= fm::kMinAlpha ? a : 0.0;
          t *= 1.0 - alpha[i];
        }
        sum += 1.0 - t;
        // Colour: front to back along d, and along -d (the view from the other side).
        double front = 1.0, back = 1.0;
        for (std::size_t k = 0; k < n; ++k) {
          const int f = order[k], b = order[n - 1 - k];
          fit.colour_weight[f] += alpha[f] * front;
          front *= 1.0 - alpha[f];
          fit.colour_weight[b] += alpha[b] * back;
          back *= 1.0 - alpha[b];
        }
      }
    covered += sum * step * step;
    merged_area += kTwoPi * std::sqrt(det_m);
  }
  fit.opacity = merged_area > 0.0 ? std::min(static_cast<double>(fm::kMaxAlpha), covered / merged_area) : 0.0;
  return fit;
}

}  // namespace catgs
