// Stage 2a', the depth-first sort's order (depth_order.cu).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// Stage 2a' (depth_order.cu, the depth-first sort): sorts the `visible` Gaussians with
// entries (records.h listed_tiles) by depth (stable, so equal depths keep index order) and rewrites ends[i] of
// each of them as the inclusive running sum of tiles_touched in that order (the others keep
// theirs). Emission then lays each Gaussian's entries out in depth order, and a stable sort on
// the tile alone (sort_pairs_narrow) gives the [tile | depth] list. `visible` comes from the
// counts readback. Returns the depth order (device, [visible] Gaussian indices; emit_keys walks
// the Gaussians in it, so consecutive threads write consecutive slots). Buffers: index and keys [2][N], count [1], temp of depth_order_temp_bytes(N);
// ends must hold N + 1 entries (a spare slot, see depth_order.cu).
struct DepthOrderBuffers {
  uint32_t* index[2];
  uint32_t* keys[2];
  unsigned* count;
  void* temp;
  std::size_t temp_bytes;
};
std::size_t depth_order_temp_bytes(uint64_t n);
const uint32_t* depth_order_ends(const uint32_t* tiles_touched, const uint32_t* chunk_total, const float* depth,
                                 uint64_t n, uint64_t visible, const DepthOrderBuffers& buffers, uint64_t* ends,
                                 cudaStream_t stream);

}  // namespace catgs::cuda::stages
