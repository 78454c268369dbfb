// Where a scene is: robust bounds and its up direction, estimated from the Gaussians' means.
// Used to place a first camera (the server's initial pose) and by the tools that build and fly
// over city-scale scenes.
#pragma once

#include <utility>

#include <glm/vec3.hpp>

#include "scene/gaussian_model.h"

namespace catgs {

// The [tail, 1 - tail] quantiles of the means projected on the unit vector `axis` (world units
// along it). Throws std::logic_error on an empty model.
std::pair<float, float> axis_quantiles(const GaussianModel& model, glm::vec3 axis, float tail);

// Bounds of the central part of a scene: per axis, the [tail, 1 - tail] quantiles of the means.
// Real captures have far floaters and sky Gaussians that make GaussianModel::bounds() useless for
// spacing copies or placing a camera. Throws std::logic_error on an empty model.
Bounds robust_bounds(const GaussianModel& model, float tail = 0.02f);

// The scene's up direction (unit, world), estimated from the means: the axis of least spread of
// the central part (ground captures are flatter than they are wide), signed so that the scene's
// bulk lies below its upper tail (ground at the bottom, objects rising from it: positive skew).
// A guess for scenes without cameras; pass an explicit up where known.
glm::vec3 estimate_up(const GaussianModel& model);

}  // namespace catgs
