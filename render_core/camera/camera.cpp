#include "camera/camera.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include <glm/gtc/quaternion.hpp>

namespace catgs {

glm::vec3 Camera::position() const { return -(glm::transpose(R) * t); }

glm::quat Camera::orientation() const { return glm::normalize(glm::quat_cast(glm::transpose(R))); }

float Camera::vertical_fov_deg() const {
  return glm::degrees(2.0f * std::atan(static_cast<float>(height) / (2.0f * fy)));
}

Camera Camera::from_pose(const glm::vec3& position, const glm::quat& camera_to_world, float vertical_fov_deg, int width,
                         int height) {
  if (!std::isfinite(position.x) || !std::isfinite(position.y) || !std::isfinite(position.z) ||
      !std::isfinite(camera_to_world.w) || !std::isfinite(camera_to_world.x) || !std::isfinite(camera_to_world.y) ||
      !std::isfinite(camera_to_world.z))
    throw std::invalid_argument("camera pose has non-finite values");
  const float len = glm::length(camera_to_world);
  if (!(len > 1e-6f)) throw std::invalid_argument("camera orientation is a zero quaternion");
  if (!(vertical_fov_deg > 0.0f && vertical_fov_deg < 180.0f))
    throw std::invalid_argument("vertical field of view must be in (0, 180) degrees");
  if (width < 1 || height < 1) throw std::invalid_argument("camera size must be positive");
  Camera c;
  const glm::mat3 c2w = glm::mat3_cast(camera_to_world / len);
  c.R = glm::transpose(c2w);
  c.t = -(c.R * position);
  c.fy = static_cast<float>(height) / (2.0f * std::tan(glm::radians(vertical_fov_deg) / 2.0f));
  c.fx = c.fy;
  c.cx = static_cast<float>(width) / 2.0f;
  c.cy = static_cast<float>(height) / 2.0f;
  c.width = width;
  c.height = height;
  return c;
}

Camera Camera::from_frustum(const glm::vec3& position, const glm::quat& camera_to_world, float angle_left,
                            float angle_right, float angle_up, float angle_down, int width, int height) {
  const float half_pi = 1.5707963f;
  for (float a : {angle_left, angle_right, angle_up, angle_down})
    if (!(std::fabs(a) < half_pi)) throw std::invalid_argument("frustum angle outside (-pi/2, pi/2)");
  if (!(angle_left < angle_right) || !(angle_down < angle_up))
    throw std::invalid_argument("frustum angles out of order (left < right, down < up)");
  // The pose's checks and rotation as from_pose (its field of view replaced below).
  Camera c = from_pose(position, camera_to_world, 90.0f, width, height);
  const float tl = std::tan(angle_left), tr = std::tan(angle_right);
  const float tu = std::tan(angle_up), td = std::tan(angle_down);
  c.fx = static_cast<float>(width) / (tr - tl);
  c.cx = -tl * c.fx;
  c.fy = static_cast<float>(height) / (tu - td);
  c.cy = tu * c.fy;
  return c;
}

Camera Camera::rescaled(int new_width, int new_height) const {
  if (new_width < 1 || new_height < 1) throw std::invalid_argument("camera size must be positive");
  Camera c = *this;
  const float sx = static_cast<float>(new_width) / static_cast<float>(width);
  const float sy = static_cast<float>(new_height) / static_cast<float>(height);
  c.fx *= sx;
  c.cx *= sx;
  c.fy *= sy;
  c.cy *= sy;
  c.width = new_width;
  c.height = new_height;
  return c;
}

void validate_camera(const Camera& c) {
  auto bad = [](const std::string& what) { throw std::invalid_argument("camera: " + what); };
  if (c.width < 1 || c.height < 1 || c.width > kMaxImageSide || c.height > kMaxImageSide)
    bad("size " + std::to_string(c.width) + "x" + std::to_string(c.height) + " outside [1, " +
        std::to_string(kMaxImageSide) + "]");
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (!std::isfinite(c.R[i][j])) bad("non-finite rotation");
  if (!std::isfinite(c.t.x) || !std::isfinite(c.t.y) || !std::isfinite(c.t.z)) bad("non-finite translation");
  if (!(c.fx > 0.0f) || !(c.fy > 0.0f) || !std::isfinite(c.fx) || !std::isfinite(c.fy) || !std::isfinite(c.cx) ||
      !std::isfinite(c.cy))
    bad("bad intrinsics");
  if (!(c.near_plane > 0.0f) || !(c.far_plane > c.near_plane)) bad("bad near/far planes");
}

}  // namespace catgs
