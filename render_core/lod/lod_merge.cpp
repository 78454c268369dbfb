// Moment-matching merge and its eigen solver (lod_merge.h).
#include "lod/lod_merge.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>
#include <vector>

#include "forward_model/forward_model.h"
#include "lod/lod_fit.h"

namespace catgs {

namespace {

// The product of the two largest of three positive values.
double two_largest(double a, double b, double c) {
  const double lo = std::min({a, b, c});
  return a * b * c / lo;
}

}  // namespace

void symmetric_eigen3(const glm::dmat3& input, glm::dvec3& values, glm::dmat3& vectors) {
  double a[3][3], v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) a[r][c] = 0.5 * (input[c][r] + input[r][c]);  // glm: [column][row]
  for (int sweep = 0; sweep < 50; ++sweep) {
    const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    const double diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
    if (off <= 1e-30 * diag || off == 0.0) break;
    for (int p = 0; p < 2; ++p)
      for (int q = p + 1; q < 3; ++q) {
        if (a[p][q] == 0.0) continue;
        // The rotation in the (p, q) plane that zeroes a[p][q] (Golub & Van Loan, Alg. 8.5.1).
        const double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
        const double t = (theta >= 0 ? 1.0 : -1.0) / (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0), s = t * c;
        for (int k = 0; k < 3; ++k) {  // a <- a J (columns p, q)
          const double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - s * akq;
          a[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 3; ++k) {  // a <- J^T a (rows p, q)
          const double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - s * aqk;
          a[q][k] = s * apk + c * aqk;
        }
        for (int k = 0; k < 3; ++k) {  // v <- v J
          const double vkp = v[k][p], vkq = v[k][q];
          v[k][p] = c * vkp - s * vkq;
          v[k][q] = s * vkp + c * vkq;
        }
      }
  }
  int order[3] = {0, 1, 2};
  std::sort(order, order + 3, [&](int x, int y) { return a[x][x] > a[y][y]; });
  for (int k = 0; k < 3; ++k) {
    values[k] = a[order[k]][order[k]];
    for (int r = 0; r < 3; ++r) vectors[k][r] = v[r][order[k]];
  }
  if (glm::determinant(vectors) < 0.0) vectors[2] = -vectors[2];
}

glm::vec4 quaternion_of(const glm::dmat3& m) {
  auto R = [&](int row, int col) { return m[col][row]; };
  const double t = R(0, 0) + R(1, 1) + R(2, 2);
  double w, x, y, z;
  if (t > 0.0) {
    const double s = 2.0 * std::sqrt(t + 1.0);
    w = 0.25 * s, x = (R(2, 1) - R(1, 2)) / s, y = (R(0, 2) - R(2, 0)) / s, z = (R(1, 0) - R(0, 1)) / s;
  } else if (R(0, 0) >= R(1, 1) && R(0, 0) >= R(2, 2)) {
    const double s = 2.0 * std::sqrt(1.0 + R(0, 0) - R(1, 1) - R(2, 2));
    w = (R(2, 1) - R(1, 2)) / s, x = 0.25 * s, y = (R(0, 1) + R(1, 0)) / s, z = (R(0, 2) + R(2, 0)) / s;
  } else if (R(1, 1) >= R(2, 2)) {
    const double s = 2.0 * std::sqrt(1.0 + R(1, 1) - R(0, 0) - R(2, 2));
    w = (R(0, 2) - R(2, 0)) / s, x = (R(0, 1) + R(1, 0)) / s, y = 0.25 * s, z = (R(1, 2) + R(2, 1)) / s;
  } else {
    const double s = 2.0 * std::sqrt(1.0 + R(2, 2) - R(0, 0) - R(1, 1));
    w = (R(1, 0) - R(0, 1)) / s, x = (R(0, 2) + R(2, 0)) / s, y = (R(1, 2) + R(2, 1)) / s, z = 0.25 * s;
  }
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  return glm::vec4(static_cast<float>(w / n), static_cast<float>(x / n), static_cast<float>(y / n),
                   static_cast<float>(z / n));
}

MergedGaussian merge_gaussians(const GaussianModel& m, const uint32_t* index, int count, float* sh_out) {
  if (count < 1) throw std::invalid_argument("merge_gaussians: nothing to merge");
  const std::size_t K3 = static_cast<std::size_t>(m.sh_coeffs()) * 3;
  auto mean_of = [&](uint32_t i) { return glm::dvec3(m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]); };
  if (count == 1) {
    const uint32_t i = index[0];
    std::copy_n(&m.sh[i * K3], K3, sh_out);
    return {glm::vec3(mean_of(i)),
            glm::vec3(m.log_scales[3 * i], m.log_scales[3 * i + 1], m.log_scales[3 * i + 2]),
            glm::vec4(m.rotations[4 * i], m.rotations[4 * i + 1], m.rotations[4 * i + 2], m.rotations[4 * i + 3]),
            m.opacity_logits[i],
            0.0f,
            1.0};
  }
  // Weights: opacity x the area of the largest cross-section (see the header).
  std::vector<double> weight(static_cast<std::size_t>(count));
  std::vector<LodFitChild> children(static_cast<std::size_t>(count));
  double w_sum = 0.0;
  for (int k = 0; k < count; ++k) {
    const uint32_t i = index[k];
    const double alpha = fm::sigmoid(m.opacity_logits[i]);
    const double area = two_largest(std::exp(m.log_scales[3 * i]), std::exp(m.log_scales[3 * i + 1]),
                                    std::exp(m.log_scales[3 * i + 2]));
    weight[k] = alpha * area;
    w_sum += weight[k];
    const fm::Cov3 s =
        fm::covariance_3d({m.log_scales[3 * i], m.log_scales[3 * i + 1], m.log_scales[3 * i + 2]},
                          {m.rotations[4 * i], m.rotations[4 * i + 1], m.rotations[4 * i + 2], m.rotations[4 * i + 3]});
    children[static_cast<std::size_t>(k)] = {mean_of(i),
                                             glm::dmat3(s.xx, s.xy, s.xz, s.xy, s.yy, s.yz, s.xz, s.yz, s.zz), alpha};
  }
  if (!(w_sum > 0.0)) {  // every input transparent or flat: an equal mix
    for (int k = 0; k < count; ++k) weight[k] = 1.0;
    w_sum = count;
  }
  glm::dvec3 mean(0.0);
  for (int k = 0; k < count; ++k) mean += weight[k] * mean_of(index[k]);
  mean /= w_sum;
  glm::dmat3 cov(0.0);
  double spread_sq = 0.0;
  for (int k = 0; k < count; ++k) {
    const glm::dvec3 d = children[static_cast<std::size_t>(k)].mean - mean;
    cov += weight[k] * (children[static_cast<std::size_t>(k)].cov + glm::outerProduct(d, d));
    spread_sq += weight[k] * glm::dot(d, d);
  }
  cov /= w_sum;
  glm::dvec3 lambda;
  glm::dmat3 axes;
  symmetric_eigen3(cov, lambda, axes);
  glm::dvec3 sigma;
  for (int a = 0; a < 3; ++a) sigma[a] = std::sqrt(std::max(lambda[a], 1e-12));
  // The merged shape's floored eigenvalues: what is drawn, so what the fit compares with.
  const glm::dmat3 drawn = axes *
                           glm::dmat3(sigma[0] * sigma[0], 0, 0, 0, sigma[1] * sigma[1], 0, 0, 0, sigma[2] * sigma[2]) *
                           glm::transpose(axes);
  const LodFit fit = fit_to_children(children.data(), count, mean, drawn, axes);
  double colour_sum = 0.0;
  for (double c : fit.colour_weight) colour_sum += c;
  for (std::size_t c = 0; c < K3; ++c) {
    double sum = 0.0;
    if (colour_sum > 0.0) {
      for (int k = 0; k < count; ++k) sum += fit.colour_weight[static_cast<std::size_t>(k)] * m.sh[index[k] * K3 + c];
      sh_out[c] = static_cast<float>(sum / colour_sum);
    } else {  // nothing drawn (every child below 1/255): an equal mix
      for (int k = 0; k < count; ++k) sum += m.sh[index[k] * K3 + c];
      sh_out[c] = static_cast<float>(sum / count);
    }
  }
  const double alpha = fit.opacity;
  // Floored above the padding's logit (is_lod_padding): a merge is never taken for padding.
  const double floor = 1.0 - kOpacityLogitLimit;
  const double logit = alpha > 0.0 ? std::max(std::log(alpha / (1.0 - alpha)), floor) : floor;
  return {glm::vec3(mean),
          glm::vec3(glm::log(sigma)),
          quaternion_of(axes),
          static_cast<float>(logit),
          static_cast<float>(std::sqrt(spread_sq / w_sum)),
          w_sum};
}

}  // namespace catgs
