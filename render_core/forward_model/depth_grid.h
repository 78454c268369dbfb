// The frame's depth grid (issue 91, "Depth with every frame"): the scene's depth at a coarse grid
// of the frame's pixels, sent with the frame so that the page can warp it as a mesh to the
// visitor's newer pose (parallax for a step sideways), answer a depth probe without a round trip,
// and let a host page place its own objects in front of or behind the scene.
//
// The depth is the *median depth* of cpu/pixel_depth.h (the depth probe's rule; 2DGS, Huang et
// al. 2024): walking the pixel's tile's sorted render list front to back with the rasterizer's
// alpha (min(0.99, opacity exp(power)), skipped where power > 0 or alpha < 1/255), the camera-space
// z of the Gaussian at which the transmittance first falls to kDepthGridTransmittance (0.5) or
// below; +inf where it never does (the pixel sees the background through the Gaussians). Walked on
// the frame's own render list, so it sees the frame's level-of-detail cut and what occlusion
// culling kept, as the picture does (entries dropped behind an opaque point cannot move a median).
//
// Grid shape for a width x height frame and a cell of `cell` pixels: vertices k = 0 .. cols - 1,
// l = 0 .. rows - 1 at image coordinates (page convention: pixel i covers [i, i + 1))
// x_k = min(k cell, width), y_l = min(l cell, height), so the first and last vertices sit on the
// image's edges. Vertex (k, l) holds the median depth of the pixel whose forward-model coordinate
// (forward_model.h: pixel i sampled at i) is (min(k cell, width - 1), min(l cell, height - 1)):
// half a pixel from the vertex, which the grid's scale (cells of 16-64 pixels) does not see.
#pragma once

#include <cstdint>

#include "forward_model/forward_model.h"

namespace catgs::fm {

inline constexpr float kDepthGridTransmittance = 0.5f;  // the median: T falls to this at the surface

CATGS_HD int depth_grid_cols(int width, int cell) { return (width + cell - 1) / cell + 1; }
CATGS_HD int depth_grid_rows(int height, int cell) { return (height + cell - 1) / cell + 1; }
// The forward-model pixel vertex k samples along an axis of `size` pixels.
CATGS_HD int depth_grid_pixel(int k, int cell, int size) { return k * cell < size - 1 ? k * cell : size - 1; }

// The alpha an entry with 2D mean `mean` (pixels), `conic` and `opacity` has at the pixel sampled
// at (px, py), as the walk counts it: 0 where the rasterizer skips it (power > 0 or alpha <
// 1/255). Depends on the entry alone, so a core may compute many entries' alphas at once.
CATGS_HD float median_walk_alpha(glm::vec2 mean, glm::vec3 conic, float opacity, float px, float py) {
  const float power = gaussian_power(conic, mean.x - px, mean.y - py);
  if (power > 0.0f) return 0.0f;
  const float alpha = fminf(kMaxAlpha, opacity * expf(power));
  return alpha < kMinAlpha ? 0.0f : alpha;
}

// One pixel's walk through its tile's list: feed entries front to back with step() (or their
// alphas with take(), in the same order); it returns true once the median is found (depth set),
// after which the caller stops. The transmittance is the serial product, in list order, on
// every core.
struct MedianDepthWalk {
  float T = 1.0f;
  float depth = INFINITY;  // camera-space z of the crossing Gaussian; +inf: none yet
  // The next entry, of alpha `alpha` (median_walk_alpha) and camera-space z `z`.
  CATGS_HD bool take(float alpha, float z) {
    if (alpha == 0.0f) return false;
    T *= 1.0f - alpha;
    if (T > kDepthGridTransmittance) return false;
    depth = z;
    return true;
  }
  // The entry with 2D mean `mean` (pixels), `conic`, `opacity` and camera-space z `z`, at the
  // pixel sampled at (px, py).
  CATGS_HD bool step(glm::vec2 mean, glm::vec3 conic, float opacity, float z, float px, float py) {
    return take(median_walk_alpha(mean, conic, opacity, px, py), z);
  }
};

}  // namespace catgs::fm
