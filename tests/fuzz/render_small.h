// The fuzz targets' render of a scene that loaded: the CPU core (exact) at 16 x 16, a camera
// looking down +z at the whole of the scene's bounds. Header-only: each target is one file plus
// replay_main.cpp.
#pragma once

#include <memory>

#include <glm/gtc/quaternion.hpp>

#include "cpu/cpu_renderer.h"

namespace catgs::fuzz {

// Renders `model` into `image` with `options` (pipeline and LOD bound as given); returns false
// without rendering when the scene's extent is 0, not finite or over 1e6 (no such camera).
inline bool render_small(const std::shared_ptr<const GaussianModel>& model, const RenderOptions& options,
                         Image& image) {
  const Bounds b = model->bounds();
  const glm::vec3 centre = 0.5f * (b.min + b.max);
  const float extent = glm::length(b.max - b.min);
  if (!(extent > 0.0f && extent < 1e6f)) return false;
  const glm::vec3 eye = centre - glm::vec3(0.0f, 0.0f, 1.5f * extent + 1e-3f);
  cpu::CpuRenderer renderer(model, options);
  renderer.render(Camera::from_pose(eye, glm::quat(1.0f, 0.0f, 0.0f, 0.0f), 60.0f, 16, 16), image);
  return true;
}

}  // namespace catgs::fuzz
