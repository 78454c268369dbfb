#include "initial_pose.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

namespace catgs::server {

Bounds robust_bounds(const GaussianModel& model) {
  const std::size_t n = model.size();
  if (n < 100) return model.bounds();
  Bounds b;
  std::vector<float> axis(n);
  for (int a = 0; a < 3; ++a) {
    for (std::size_t i = 0; i < n; ++i) axis[i] = model.means[3 * i + static_cast<std::size_t>(a)];
    const auto lo = static_cast<std::ptrdiff_t>(n * 2 / 100);
    const auto hi = static_cast<std::ptrdiff_t>(n * 98 / 100);
    std::nth_element(axis.begin(), axis.begin() + lo, axis.end());
    b.min[a] = axis[static_cast<std::size_t>(lo)];
    std::nth_element(axis.begin(), axis.begin() + hi, axis.end());
    b.max[a] = axis[static_cast<std::size_t>(hi)];
  }
  return b;
}

CameraPose initial_pose(const Bounds& bounds, float fov_deg, int width, int height) {
  const glm::vec3 centre = bounds.center();
  const float radius = std::max(0.5f * glm::length(bounds.extent()), 1e-3f);
  const float vfov = glm::radians(fov_deg);
  const float hfov = 2.0f * std::atan(std::tan(vfov / 2.0f) * static_cast<float>(width) /
                                      static_cast<float>(std::max(height, 1)));
  const float half = 0.5f * std::min(vfov, hfov);
  const float distance = radius / std::sin(half);
  // In front (-z) and raised by ~17 degrees towards world up (-y).
  const glm::vec3 offset_dir = glm::normalize(glm::vec3(0.0f, -0.3f, -1.0f));
  CameraPose pose;
  pose.position = centre + distance * offset_dir;
  const glm::vec3 forward = glm::normalize(centre - pose.position);   // camera +z
  const glm::vec3 down(0.0f, 1.0f, 0.0f);                              // world down
  const glm::vec3 right = glm::normalize(glm::cross(down, forward));  // camera +x
  const glm::vec3 cam_down = glm::cross(forward, right);               // camera +y
  pose.orientation = glm::normalize(glm::quat_cast(glm::mat3(right, cam_down, forward)));
  pose.vertical_fov_deg = fov_deg;
  return pose;
}

}  // namespace catgs::server
