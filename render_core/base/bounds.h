// An axis-aligned box in world units: a scene's extent (GaussianModel::bounds, robust_bounds) and
// the centre the synthetic camera paths circle (camera/trace.h).
#pragma once

#include <glm/vec3.hpp>

namespace catgs {

struct Bounds {
  glm::vec3 min{0.0f};
  glm::vec3 max{0.0f};
  glm::vec3 center() const { return 0.5f * (min + max); }
  glm::vec3 extent() const { return max - min; }
};

}  // namespace catgs
