// Median kd clustering of a LOD node's Gaussians (lod_cluster.h).
#include "lod/lod_cluster.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace catgs {

namespace {

// The axis (0..2) along which the means of items[lo, hi) spread most (largest box side).
int widest_axis(const float* means, const std::vector<uint32_t>& items, std::size_t lo, std::size_t hi) {
  float mn[3] = {INFINITY, INFINITY, INFINITY}, mx[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (std::size_t k = lo; k < hi; ++k)
    for (int a = 0; a < 3; ++a) {
      mn[a] = std::min(mn[a], means[3 * std::size_t{items[k]} + a]);
      mx[a] = std::max(mx[a], means[3 * std::size_t{items[k]} + a]);
    }
  int axis = 0;
  for (int a = 1; a < 3; ++a)
    if (mx[a] - mn[a] > mx[axis] - mn[axis]) axis = a;
  return axis;
}

// Splits items[lo, hi) into `clusters` groups whose bounds start at bounds[first].
void split(const float* means, std::vector<uint32_t>& items, std::size_t lo, std::size_t hi, std::size_t clusters,
           std::size_t first, std::vector<std::size_t>& bounds) {
  if (clusters == 1) {
    bounds[first] = lo;
    return;
  }
  const std::size_t left = clusters / 2;
  // The left half's share of the items, so every group ends up with floor or ceil of the mean
  // (the same rounding at every depth: item counts split as (n * left) / clusters).
  const std::size_t mid = lo + (hi - lo) * left / clusters;
  if (hi - lo > 1 && mid > lo && mid < hi) {
    const int axis = widest_axis(means, items, lo, hi);
    std::nth_element(items.begin() + static_cast<std::ptrdiff_t>(lo), items.begin() + static_cast<std::ptrdiff_t>(mid),
                     items.begin() + static_cast<std::ptrdiff_t>(hi), [&](uint32_t x, uint32_t y) {
                       return means[3 * std::size_t{x} + axis] < means[3 * std::size_t{y} + axis];
                     });
  }
  split(means, items, lo, mid, left, first, bounds);
  split(means, items, mid, hi, clusters - left, first + left, bounds);
}

}  // namespace

std::vector<std::size_t> kd_clusters(const float* means, std::vector<uint32_t>& items, std::size_t clusters) {
  if (clusters < 1) throw std::invalid_argument("kd_clusters: clusters must be >= 1");
  std::vector<std::size_t> bounds(clusters + 1, items.size());
  split(means, items, 0, items.size(), clusters, 0, bounds);
  return bounds;
}

}  // namespace catgs
