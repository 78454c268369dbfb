// Internal: front-to-back blending of a run of the sorted render list over one tile's pixels,
// shared by rasterize.cpp (one run per tile) and rasterize_slices.cpp (one run per slice).
#pragma once

#include "cpu/cpu_renderer.h"

namespace catgs::cpu {

inline constexpr int kTilePixels = fm::kTileSize * fm::kTileSize;

// Blends entries [begin, end) of `list` into tile (tx, ty): C and T hold [16 * 16] pixels,
// row-major in the tile, and must start at (0, 1). Per pixel it does exactly what the reference
// loop does (alpha = min(0.99, opacity * exp(power)), skip below 1/255, stop before T < 1e-4 when
// early_termination), but a Gaussian visits only the pixels of its q <= q_max box: outside it
// alpha < 1/255 and the reference would skip it too, so the image is bit-identical.
// `stopped` (null, or [16 * 16] set to false by the caller): true where a pixel stopped by early
// termination (rasterize_slices: its composition ends with this slice). `occluded_at` (null, or
// [16 * 16] set to UINT32_MAX by the caller): the list position of the entry at which the pixel
// stopped or after which its T fell below fm::kOcclusionTransmittance (the occlusion map).
// `changed` (null, or [list length]): set to 1 for each entry blended at some pixel while that
// pixel's T was still above fm::kOcclusionTransmittance (issue 72's "changes any pixel").
void blend_tile(const ProjectedGaussians& projected, const RenderList& list, uint32_t begin, uint32_t end, int tx,
                int ty, const TileGrid& grid, bool early_termination, glm::vec3* C, float* T, bool* stopped = nullptr,
                uint32_t* occluded_at = nullptr, uint8_t* changed = nullptr);

}  // namespace catgs::cpu
