// Stage 4 of the CUDA core (tile_ranges.cu; mirrors cpu/tile_ranges.cpp).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// Stage 4 (tile_ranges.cu): [start, end) of each tile in the sorted list; tiles without entries get
// [0, 0). Sentinel entries (tile id >= tiles) are ignored. Keys are 64-bit or 32-bit, made as
// `packing` says (forward_model/key_packing.h).
void tile_ranges(const uint64_t* sorted_keys, DepthKeyPacking packing, uint64_t entries, uint32_t tiles, uint2* ranges,
                 cudaStream_t stream);
void tile_ranges(const uint32_t* sorted_keys, DepthKeyPacking packing, uint64_t entries, uint32_t tiles, uint2* ranges,
                 cudaStream_t stream);

// Stage 4b (tile_ranges.cu): tile ids by decreasing number of entries, to within a quarter of an
// octave (one block: a histogram of the loads' leading bits, then a scatter), so the
// rasterizer's blocks start on the heaviest tiles and the light ones fill in behind them
// (longest-processing-time-first scheduling) instead of the heavy tiles of the bottom rows
// starting last. Writes the heaviest tile's entries to *heaviest.
void order_tiles(const uint2* ranges, uint32_t tiles, uint32_t* order, uint32_t* heaviest, cudaStream_t stream);

}  // namespace catgs::cuda::stages
