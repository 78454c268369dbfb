// Spatial order of a scene's Gaussians (catgs-scene compact: tight SuperSplat chunks).
#pragma once

#include <cstdint>
#include <vector>

#include "scene/gaussian_model.h"

namespace catgs {

// Permutation that sorts Gaussians along a 3D Morton (Z-order) curve over the robust bounds, so
// runs of 256 (SuperSplat compressed PLY chunks) are spatially tight.
std::vector<uint32_t> morton_order(const GaussianModel& model);
// The model with its Gaussians in `order` (a permutation of 0..N-1).
GaussianModel permuted(const GaussianModel& model, const std::vector<uint32_t>& order);

}  // namespace catgs
