// What a merged Gaussian's children draw (issue 72): the opacity and the colour weights of a
// merged Gaussian fitted to its children's drawing, the step Hierarchical 3DGS (Kerbl et al.,
// SIGGRAPH 2024, sec. 5) takes by optimising its interior nodes against the training images. We
// have no images, so the target is the children themselves, drawn as the supersampled reference
// draws them (their own covariances, no low-pass), seen along seven directions.
//
// Why not a closed form: optical depth averaged over the merged area (the rule before this one)
// is exact for children stacked on one another, but a cluster with gaps (foliage, a fence) lets
// light through where no child lies, and averaging depth over the gaps makes the merge far more
// opaque than the cluster (exp is convex: the mean of exp(-tau) is above exp(-mean tau)).
// Summing coverage is exact for children side by side and wrong for stacked ones. Drawing the
// children is right for both. (Measured: docs/history/level_of_detail.md, "Fitted merges".)
#pragma once

#include <vector>

#include <glm/glm.hpp>

namespace catgs {

// One child as the fit reads it: mean (world units), 3D covariance (world units^2), peak opacity
// in (0, 1).
struct LodFitChild {
  glm::dvec3 mean;
  glm::dmat3 cov;
  double alpha;
};

// What the children draw, against the merged Gaussian of mean `mean`, covariance `cov` (world;
// the moment match of lod_merge.h) and principal axes `axes` (columns, symmetric_eigen3's).
// Seven view directions in the merged Gaussian's frame (its three axes, face-on and edge-on, and
// the four diagonals (+-1, +-1, 1) / sqrt 3 between them); along each, an orthographic drawing:
// - coverage: the children's alpha composited, A(x) = 1 - prod_i (1 - alpha_i(x)), alpha_i(x) =
//   min(0.99, alpha_i exp(-q_i(x) / 2)) left out below 1/255 as the rasterizer does, summed over
//   a 12 x 12 grid spanning +-3.5 std devs of the merged Gaussian's projection (each child widened
//   by a quarter of the grid step squared, its peak lowered so its integral stays, so that a
//   child narrower than the grid is still counted whole);
// - `opacity`: the merged peak alpha whose Gaussian covers as much, summed over the directions:
//   sum_d integral A_d / sum_d 2 pi sqrt(det Sigma_d), Sigma_d the merged projection, at most 0.99
//   (kMaxAlpha). The renderer keeps that integral at any distance for a merged Gaussian
//   (fm::merged_opacity);
// - `colour_weight[i]`: child i's share of the drawing's colour, alpha_i(x) T_i(x) summed over the
//   grid, the directions, and both ways along each (a view from either side), T_i the
//   transmittance in front of it.
// `count` >= 1 children; throws std::invalid_argument otherwise.
struct LodFit {
  double opacity = 0;
  std::vector<double> colour_weight;
};
LodFit fit_to_children(const LodFitChild* children, int count, const glm::dvec3& mean, const glm::dmat3& cov,
                       const glm::dmat3& axes);

}  // namespace catgs
