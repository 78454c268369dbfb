// Pinhole camera, OpenCV/COLMAP axes: x right, y down, z forward (docs/DESIGN.md "Forward model").
#pragma once

#include <glm/gtc/quaternion.hpp>
#include <glm/mat3x3.hpp>
#include <glm/vec3.hpp>

namespace catgs {

inline constexpr float kDefaultNear = 0.2f;  // reference 3DGS near plane
inline constexpr float kDefaultFar = 1000.0f;
inline constexpr int kMaxImageSide = 8192;  // the largest image side a renderer draws, pixels

// A camera. World-to-camera: x_cam = R * x_world + t. Intrinsics in pixels of the output image;
// (cx, cy) is in continuous image coordinates where pixel (i, j) covers [i, i+1) x [j, j+1)
// (so the image centre is (width / 2, height / 2)).
struct Camera {
  glm::mat3 R{1.0f};                                         // world-to-camera rotation
  glm::vec3 t{0.0f};                                         // world-to-camera translation
  float fx = 1.0f, fy = 1.0f, cx = 0.0f, cy = 0.0f;          // pixels
  int width = 0, height = 0;                                 // pixels
  float near_plane = kDefaultNear, far_plane = kDefaultFar;  // camera-space z, world units

  // Camera centre in world coordinates (-R^T t).
  glm::vec3 position() const;
  // Camera-to-world rotation as a unit quaternion (columns of R^T: camera x, y, z in world).
  glm::quat orientation() const;
  // Vertical field of view, degrees.
  float vertical_fov_deg() const;

  // Builds a camera from its centre (world), camera-to-world rotation, full vertical field of view
  // in degrees and image size; square pixels, principal point at the image centre.
  // Throws std::invalid_argument for non-finite input, fov outside (0, 180) or a size < 1.
  static Camera from_pose(const glm::vec3& position, const glm::quat& camera_to_world, float vertical_fov_deg,
                          int width, int height);

  // Builds a camera whose frustum has the given edges (issue 94: a headset's eye, OpenXR's XrFovf
  // and WebXR's XRView projection): `angle_left` < `angle_right` and `angle_down` < `angle_up`,
  // radians from the forward axis, each in (-pi/2, pi/2) (left and down negative). The frustum
  // may be asymmetric: fx = width / (tan(right) - tan(left)), cx = -tan(left) fx, and with y
  // down fy = height / (tan(up) - tan(down)), cy = tan(up) fy; pixels are square only where the
  // size's aspect is the frustum's. Throws std::invalid_argument as from_pose does, and for
  // angles out of order or range.
  static Camera from_frustum(const glm::vec3& position, const glm::quat& camera_to_world, float angle_left,
                             float angle_right, float angle_up, float angle_down, int width, int height);

  // The same view for another image size: scales fx, cx by width ratio and fy, cy by height ratio.
  Camera rescaled(int new_width, int new_height) const;
};

// Checks a camera a renderer can draw: size in [1, kMaxImageSide], finite R, t and intrinsics,
// fx, fy > 0, 0 < near < far. Throws std::invalid_argument saying what is wrong.
void validate_camera(const Camera& camera);

}  // namespace catgs
