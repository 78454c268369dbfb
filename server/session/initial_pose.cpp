#include "session/initial_pose.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include "scene/scene_bounds.h"

namespace catgs::server {

Bounds first_view_bounds(const GaussianModel& model) {
  // Too few Gaussians for quantiles to mean anything: all of them.
  return model.size() < 100 ? model.bounds() : robust_bounds(model, 0.02f);
}

CameraPose initial_pose(const Bounds& bounds, float fov_deg, int width, int height) {
  const glm::vec3 centre = bounds.center();
  const float radius = std::max(0.5f * glm::length(bounds.extent()), 1e-3f);
  const float vfov = glm::radians(fov_deg);
  const float hfov =
      2.0f * std::atan(std::tan(vfov / 2.0f) * static_cast<float>(width) / static_cast<float>(std::max(height, 1)));
  const float half = 0.5f * std::min(vfov, hfov);
  const float distance = radius / std::sin(half);
  // In front (-z) and raised by ~17 degrees towards world up (-y).
  const glm::vec3 offset_dir = glm::normalize(glm::vec3(0.0f, -0.3f, -1.0f));
  CameraPose pose;
  pose.position = centre + distance * offset_dir;
  const glm::vec3 forward = glm::normalize(centre - pose.position);   // camera +z
  const glm::vec3 down(0.0f, 1.0f, 0.0f);                             // world down
  const glm::vec3 right = glm::normalize(glm::cross(down, forward));  // camera +x
  const glm::vec3 cam_down = glm::cross(forward, right);              // camera +y
  pose.orientation = glm::normalize(glm::quat_cast(glm::mat3(right, cam_down, forward)));
  pose.vertical_fov_deg = fov_deg;
  return pose;
}

}  // namespace catgs::server
