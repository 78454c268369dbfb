// Depth probe: what lies under one pixel of a view (issue 38: hotspots, measurements, walk mode).
//
// The probe follows the pixel's ray through the same forward model the cores render with
// (forward_model.h): every Gaussian's EWA ellipse is evaluated at the pixel, the ones with alpha
// >= 1/255 are composited front to back by camera-space depth, and the pixel's depth is the
// *median depth*: the depth of the Gaussian at which the transmittance T first falls to 0.5 or
// below (the convention of median-depth rendering in 2DGS, Huang et al. 2024, and of "depth under
// the cursor" in splat viewers). A ray whose T stays above 0.5 has no surface. The median is
// used rather than the expected depth sum(z a T) / sum(a T) because the expectation of a ray that
// grazes a foreground edge lands between the two surfaces, in empty space.
//
// It reads the host model, so it answers the same for a CPU and a CUDA server (the CUDA core
// would need a second path for a one-pixel render). It visits every Gaussian once, serially (a
// cheap screen-radius test first), or, given the chunk bounds, only the chunks that may reach the
// pixel: made for a click or a few probes a second, not for every pixel of a frame;
// docs/history/depth_probe.md has its time.
#pragma once

#include <cstddef>
#include <vector>

#include <glm/glm.hpp>

#include "camera/camera.h"
#include "forward_model/chunk_bounds.h"
#include "scene/gaussian_model.h"

namespace catgs::cpu {

inline constexpr float kSurfaceTransmittance = 0.5f;  // the median: T falls to this at the surface

struct PixelDepth {
  bool hit = false;              // T fell to kSurfaceTransmittance or below
  float depth = 0.0f;            // hit: camera-space z of that Gaussian's mean, world units
  glm::vec3 point{0.0f};         // hit: world point on the pixel's ray at camera-space z = depth
  float opacity = 0.0f;          // 1 - T after the whole ray (the renderer's stop rule), 0..1
  std::size_t contributors = 0;  // Gaussians with alpha >= 1/255 at the pixel
};

// Probes the pixel at continuous image coordinates (x, y) of `camera` (x in [0, width): the centre
// of pixel i is i + 0.5, as (cx, cy); forward_model.h samples pixel i at i in its pixel units, so
// the probe samples at (x - 0.5, y - 0.5) there). The world point is camera centre + R^T (depth *
// ((x - cx) / fx, (y - cy) / fy, 1)). Throws std::invalid_argument (what validate_camera throws,
// or a pixel outside the image or not finite).
// `chunks` (optional, chunk_bounds_of(model)) skips whole chunks of 256 Gaussians that cannot
// reach the pixel, the renderer's own conservative chunk test: the answer is the same with or
// without them, only faster on scenes in Morton order (catgs-scene compact). A scene with LOD
// (forward_model/lod.h) is probed at full detail: its leaves only.
PixelDepth probe_pixel_depth(const GaussianModel& model, const Camera& camera, double x, double y,
                             const std::vector<fm::ChunkBounds>* chunks = nullptr);

}  // namespace catgs::cpu
