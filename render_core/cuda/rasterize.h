// Stage 5 of the CUDA core (rasterize.cu; mirrors cpu/rasterize.cpp).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// Stage 5 (rasterize.cu): one block per tile, front-to-back blending; writes float RGB and packed
// 8-bit RGBA (R | G << 8 | B << 16 | 255 << 24) in device memory. `tile_order` [tiles]: block b
// rasterizes tile first_tile + tile_order[b] (order_tiles over ranges + first_tile: the heaviest
// first), for b < tile_count: a pass of a frame drawn in passes draws its region's tiles only.
void rasterize(const uint2* ranges, const uint32_t* tile_order, uint32_t first_tile, uint32_t tile_count,
               const uint32_t* sorted_values, const Projected& projected, const CameraParams& cam, float3 background,
               float* out_rgb, uint32_t* out_rgba8, cudaStream_t stream);

}  // namespace catgs::cuda::stages
