// Merging Gaussians for level of detail (issue 37): moment matching, the merge of Hierarchical
// 3DGS (Kerbl et al., SIGGRAPH 2024, sec. 4) for the shape, a fit to the children's drawing for the
// opacity and colour (lod_fit.h), and the 3x3 eigen solver it needs to turn the
// merged covariance back into a scale and a rotation. lod_build.h builds the tree with it.
#pragma once

#include <cstdint>

#include <glm/glm.hpp>

#include "scene/gaussian_model.h"

namespace catgs {

// Log-scale of the invisible Gaussians that pad a merged level's chunk (an empty cluster; opacity
// logit -kOpacityLogitLimit): a std dev of 2e-9 world units, so a padding Gaussian neither widens a
// chunk's bounds nor draws. A leaf chunk's padding is an invisible copy of its first Gaussian
// instead (lod_build.h), so that the chunk's quantization ranges stay its Gaussians'.
inline constexpr float kLodPadLogScale = -20.0f;

// A Gaussian that pads a chunk (lod_build.h): opacity logit at or below -kOpacityLogitLimit.
inline bool is_lod_padding(float opacity_logit) { return opacity_logit <= -kOpacityLogitLimit; }

// One merged Gaussian, in GaussianModel's units and frames (world units, log std devs, a unit
// (w, x, y, z) quaternion, an opacity logit); `spread` is the weighted RMS distance from `mean`
// of the means of the Gaussians merged into it, sqrt(sum w_i |mu_i - mu|^2 / sum w_i) (world
// units; 0 for a single Gaussian), and `weight` sum w_i (below): the run's part of its node's
// error (lod_build.h).
struct MergedGaussian {
  glm::vec3 mean;
  glm::vec3 log_scale;
  glm::vec4 rotation;
  float opacity_logit;
  float spread;
  double weight;
};

// Merges the `count` >= 1 Gaussians `index[0..count)` of `model` into one, writing its SH
// coefficients (model.sh_coeffs() x 3, coefficient-major as GaussianModel) to `sh_out`:
// - weight w_i = alpha_i a_i, alpha_i = sigmoid(logit_i), a_i the product of its two largest std
//   devs (the area of its largest cross-section, over pi): what it covers on screen when seen
//   face-on, the H3DGS weight (opacity times surface); all weights 0 falls back to equal ones;
// - mean = sum w_i mu_i / sum w_i; covariance = sum w_i (Sigma_i + (mu_i - mu)(mu_i - mu)^T) /
//   sum w_i (the moments of the weighted mixture);
// - SH: the mean of the coefficients weighted by each child's share of what the children draw
//   (lod_fit.h colour_weight: its alpha times the transmittance in front of it, over seven view
//   directions both ways; nothing drawn: an equal mix);
// - scale and rotation: the covariance's eigen decomposition (symmetric_eigen3), eigenvalues
//   floored at 1e-12 (a flat merge stays drawable);
// - opacity: the peak alpha whose Gaussian covers what the children's composite covers, over the
//   same directions (lod_fit.h opacity), drawn with its integral kept at any distance
//   (fm::drawn_opacity). The rule before it kept optical depth over the merged area, which
//   spreads a child's depth over the gaps between children: merges far too opaque (measured:
//   docs/history/level_of_detail.md, "Fitted merges").
// One input returns that Gaussian unchanged (spread 0); in a merged level it is still drawn with
// its coverage kept (fm::drawn_opacity), as the supersampled reference covers it. Throws std::invalid_argument for count
// < 1.
MergedGaussian merge_gaussians(const GaussianModel& model, const uint32_t* index, int count, float* sh_out);

// Eigen decomposition of the symmetric 3x3 matrix `a` by cyclic Jacobi rotations (Golub & Van
// Loan, Matrix Computations, sec. 8.5): a = V diag(values) V^T, V orthonormal with det +1
// (columns: the eigenvectors), values in descending order. Converges to double rounding for any
// finite input.
void symmetric_eigen3(const glm::dmat3& a, glm::dvec3& values, glm::dmat3& vectors);

// The unit quaternion (w, x, y, z) of rotation matrix `r` (det +1; columns are the rotated axes,
// as fm::quat_to_mat returns), by Shepperd's method (the largest of w, x, y, z first).
glm::vec4 quaternion_of(const glm::dmat3& r);

}  // namespace catgs
