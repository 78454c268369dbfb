// Occlusion culling's two small stages of the CUDA core's exact frames (occlusion_map.cu; mirror
// cpu/occlusion_map.cpp). Raw device pointers and an explicit stream; the launcher checks its
// launch (CudaError).
#pragma once

#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// The occlusion map (forward_model/occlusion.h) of tiles [first_tile, end_tile), a thread per
// tile: tile_depth[t] = the view depth of the entry before the tile's opaque point P
// (opaque_at[t], rasterize_slices' tile_opaque_at), the largest finite float where P is all ones
// ("never opaque"); adds the entries at or behind P (ranges[t].y - P) to *behind (zero it before
// the frame). `values`: the sorted list's slots, `projected.depth` their depths.
void occlusion_map(const uint32_t* opaque_at, const uint2* ranges, const uint32_t* values, const Projected& projected,
                   uint32_t first_tile, uint32_t end_tile, float* tile_depth, unsigned long long* behind,
                   cudaStream_t stream);

// Before pre-processing: the last frame's per-pixel map (`last_pixels`, [last's pixels], drawn at
// `last`) reprojected onto `now` (mirrors cpu::occlusion_reproject): every quad of fm::occlusion_quad
// drawn with a depth test into `now_pixels` ([now's pixels], scratch), then the deepest per cell
// into `cells` ([fm::occlusion_cell_count]). Returns the map over `cells`.
fm::OcclusionMap occlusion_reproject(const float* last_pixels, const fm::View& last, const fm::View& now,
                                     unsigned* now_pixels, float* cells, cudaStream_t stream);

}  // namespace catgs::cuda::stages
