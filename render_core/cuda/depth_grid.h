// Stage 5b of the CUDA core (depth_grid.cu; mirrors cpu/depth_grid.cpp): the frame's depth grid
// (forward_model/depth_grid.h). Raw device pointers and an explicit stream; the launcher checks
// its launch (CudaError).
#pragma once

#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// Writes out[l * cols + k] (cols x rows of depth_grid_cols/rows(cam's size, cell)) for every
// vertex whose pixel lies in tiles [first_tile, end_tile): its median depth over the tile's
// sorted range, +inf where the transmittance never falls to 0.5.
void depth_grid(const uint2* ranges, const uint32_t* sorted_values, const Projected& projected, const CameraParams& cam,
                int cell, uint32_t first_tile, uint32_t end_tile, float* out, cudaStream_t stream);

}  // namespace catgs::cuda::stages
