#include "scene/scene_bounds.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include <glm/glm.hpp>

namespace catgs {

namespace {

// Eigen-decomposition of a symmetric 3x3 matrix (cyclic Jacobi), eigenvectors in columns of V.
void jacobi_eigen(double A[3][3], double V[3][3], double w[3]) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) V[i][j] = i == j ? 1.0 : 0.0;
  for (int sweep = 0; sweep < 50; ++sweep) {
    const double off = A[0][1] * A[0][1] + A[0][2] * A[0][2] + A[1][2] * A[1][2];
    if (off < 1e-30) break;
    for (int p = 0; p < 2; ++p)
      for (int q = p + 1; q < 3; ++q) {
        if (std::fabs(A[p][q]) < 1e-300) continue;
        const double theta = (A[q][q] - A[p][p]) / (2.0 * A[p][q]);
        const double t = (theta >= 0 ? 1.0 : -1.0) / (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0), s = t * c;
        for (int k = 0; k < 3; ++k) {  // A = J^T A J
          const double akp = A[k][p], akq = A[k][q];
          A[k][p] = c * akp - s * akq;
          A[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 3; ++k) {
          const double apk = A[p][k], aqk = A[q][k];
          A[p][k] = c * apk - s * aqk;
          A[q][k] = s * apk + c * aqk;
        }
        for (int k = 0; k < 3; ++k) {
          const double vkp = V[k][p], vkq = V[k][q];
          V[k][p] = c * vkp - s * vkq;
          V[k][q] = s * vkp + c * vkq;
        }
      }
  }
  for (int i = 0; i < 3; ++i) w[i] = A[i][i];
}

}  // namespace

std::pair<float, float> axis_quantiles(const GaussianModel& m, glm::vec3 axis, float tail) {
  const std::size_t n = m.size();
  if (n == 0) throw std::logic_error("quantiles of an empty Gaussian model");
  std::vector<float> v(n);
  for (std::size_t i = 0; i < n; ++i)
    v[i] = axis.x * m.means[3 * i] + axis.y * m.means[3 * i + 1] + axis.z * m.means[3 * i + 2];
  const auto lo_k = static_cast<std::size_t>(static_cast<double>(tail) * static_cast<double>(n - 1));
  const auto hi_k = static_cast<std::size_t>(static_cast<double>(1.0f - tail) * static_cast<double>(n - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(lo_k), v.end());
  const float lo = v[lo_k];
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(hi_k), v.end());
  return {lo, v[hi_k]};
}

Bounds robust_bounds(const GaussianModel& model, float tail) {
  Bounds b;
  for (int a = 0; a < 3; ++a) {
    glm::vec3 axis(0.0f);
    axis[a] = 1.0f;
    const auto [lo, hi] = axis_quantiles(model, axis, tail);
    b.min[a] = lo;
    b.max[a] = hi;
  }
  return b;
}

glm::vec3 estimate_up(const GaussianModel& model) {
  const Bounds rb = robust_bounds(model, 0.02f);
  double mean[3] = {0, 0, 0}, C[3][3] = {};
  std::size_t count = 0;
  auto inside = [&](std::size_t i) {
    for (int a = 0; a < 3; ++a)
      if (model.means[3 * i + a] < rb.min[a] || model.means[3 * i + a] > rb.max[a]) return false;
    return true;
  };
  for (std::size_t i = 0; i < model.size(); ++i)
    if (inside(i)) {
      for (int a = 0; a < 3; ++a) mean[a] += model.means[3 * i + a];
      ++count;
    }
  if (count < 3) return {0.0f, -1.0f, 0.0f};
  for (double& m : mean) m /= static_cast<double>(count);
  for (std::size_t i = 0; i < model.size(); ++i)
    if (inside(i))
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) C[a][b] += (model.means[3 * i + a] - mean[a]) * (model.means[3 * i + b] - mean[b]);
  double V[3][3], w[3];
  jacobi_eigen(C, V, w);
  int k = 0;
  for (int a = 1; a < 3; ++a)
    if (w[a] < w[k]) k = a;
  glm::vec3 up(static_cast<float>(V[0][k]), static_cast<float>(V[1][k]), static_cast<float>(V[2][k]));
  up = glm::normalize(up);
  double m3 = 0.0;  // third central moment along up
  for (std::size_t i = 0; i < model.size(); ++i)
    if (inside(i)) {
      double h = 0.0;
      for (int a = 0; a < 3; ++a) h += (model.means[3 * i + a] - mean[a]) * up[a];
      m3 += h * h * h;
    }
  return m3 < 0.0 ? -up : up;
}

}  // namespace catgs
