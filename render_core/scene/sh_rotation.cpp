#include "scene/sh_rotation.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <utility>

#include <glm/glm.hpp>

namespace catgs {

namespace {

// Real SH basis of forward_model.h's sh_to_color (same constants and signs), band l only,
// at unit direction d: out[0 .. 2l].
void sh_band(int l, const double d[3], double* out) {
  const double x = d[0], y = d[1], z = d[2];
  const double C1 = 0.4886025119029199;
  const double xx = x * x, yy = y * y, zz = z * z;
  switch (l) {
    case 1:
      out[0] = -C1 * y;
      out[1] = C1 * z;
      out[2] = -C1 * x;
      break;
    case 2:
      out[0] = 1.0925484305920792 * x * y;
      out[1] = -1.0925484305920792 * y * z;
      out[2] = 0.31539156525252005 * (2.0 * zz - xx - yy);
      out[3] = -1.0925484305920792 * x * z;
      out[4] = 0.5462742152960396 * (xx - yy);
      break;
    case 3:
      out[0] = -0.5900435899266435 * y * (3.0 * xx - yy);
      out[1] = 2.890611442640554 * x * y * z;
      out[2] = -0.4570457994644658 * y * (4.0 * zz - xx - yy);
      out[3] = 0.3731763325901154 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
      out[4] = -0.4570457994644658 * x * (4.0 * zz - xx - yy);
      out[5] = 1.445305721320277 * z * (xx - yy);
      out[6] = -0.5900435899266435 * x * (xx - 3.0 * yy);
      break;
    default:
      break;
  }
}

// Solves A X = B for X (n x n, n <= 7, several right-hand sides) by Gaussian elimination with
// partial pivoting; A and B are overwritten.
void solve(int n, double A[7][7], double B[7][7]) {
  for (int c = 0; c < n; ++c) {
    int piv = c;
    for (int r = c + 1; r < n; ++r)
      if (std::fabs(A[r][c]) > std::fabs(A[piv][c])) piv = r;
    std::swap(A[c], A[piv]);
    std::swap(B[c], B[piv]);
    for (int r = 0; r < n; ++r) {
      if (r == c) continue;
      const double f = A[r][c] / A[c][c];
      for (int k = 0; k < n; ++k) {
        A[r][k] -= f * A[c][k];
        B[r][k] -= f * B[c][k];
      }
    }
  }
  for (int r = 0; r < n; ++r)
    for (int k = 0; k < n; ++k) B[r][k] /= A[r][r];
}

}  // namespace

ShRotation make_sh_rotation(int degree, const glm::mat3& R) {
  ShRotation rot;
  rot.degree = degree;
  constexpr int kSamples = 64;  // Fibonacci sphere: well spread, deterministic
  std::array<std::array<double, 3>, kSamples> dirs{}, rotated{};
  const glm::dmat3 Rt = glm::transpose(glm::dmat3(R));
  for (int k = 0; k < kSamples; ++k) {
    const double z = 1.0 - (2.0 * k + 1.0) / kSamples;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = k * 2.399963229728653;
    dirs[static_cast<std::size_t>(k)] = {r * std::cos(phi), r * std::sin(phi), z};
    const glm::dvec3 d(r * std::cos(phi), r * std::sin(phi), z);
    const glm::dvec3 q = Rt * d;  // the old direction that now looks along d
    rotated[static_cast<std::size_t>(k)] = {q.x, q.y, q.z};
  }
  for (int l = 1; l <= degree; ++l) {
    const int m = 2 * l + 1;
    double AtA[7][7] = {}, AtB[7][7] = {};
    for (int k = 0; k < kSamples; ++k) {
      double a[7], b[7];
      sh_band(l, dirs[static_cast<std::size_t>(k)].data(), a);
      sh_band(l, rotated[static_cast<std::size_t>(k)].data(), b);
      for (int i = 0; i < m; ++i)
        for (int j = 0; j < m; ++j) {
          AtA[i][j] += a[i] * a[j];
          AtB[i][j] += a[i] * b[j];
        }
    }
    solve(m, AtA, AtB);  // AtB = M: c' = M c
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < m; ++j) rot.band[l][i][j] = AtB[i][j];
  }
  return rot;
}

void ShRotation::apply(float* sh) const {
  for (int l = 1; l <= degree; ++l) {
    const int m = 2 * l + 1, first = l * l;
    for (int c = 0; c < 3; ++c) {
      double in[7], out[7];
      for (int j = 0; j < m; ++j) in[j] = sh[(first + j) * 3 + c];
      for (int i = 0; i < m; ++i) {
        out[i] = 0.0;
        for (int j = 0; j < m; ++j) out[i] += band[l][i][j] * in[j];
      }
      for (int i = 0; i < m; ++i) sh[(first + i) * 3 + c] = static_cast<float>(out[i]);
    }
  }
}

void rotate_sh(int degree, float* sh, const glm::mat3& R) { make_sh_rotation(degree, R).apply(sh); }

}  // namespace catgs
