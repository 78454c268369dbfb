// Warp-wide reductions over all 32 lanes (full mask), for every GPU the CUDA image is built for
// (docker/Dockerfile.cuda: sm_75 to sm_90). sm_80 and later reduce in one instruction
// (__reduce_*_sync, redux.sync); sm_75 (T4) has no redux, so there five butterfly shuffles give
// the same value in every lane.
#pragma once

#include <cstdint>

namespace catgs::cuda::stages {

__device__ __forceinline__ uint32_t warp_sum(uint32_t v) {
#if __CUDA_ARCH__ >= 800
  return __reduce_add_sync(0xffffffffu, v);
#else
  for (int offset = 16; offset > 0; offset >>= 1) v += __shfl_xor_sync(0xffffffffu, v, offset);
  return v;
#endif
}

__device__ __forceinline__ uint32_t warp_max(uint32_t v) {
#if __CUDA_ARCH__ >= 800
  return __reduce_max_sync(0xffffffffu, v);
#else
  for (int offset = 16; offset > 0; offset >>= 1) v = max(v, __shfl_xor_sync(0xffffffffu, v, offset));
  return v;
#endif
}

}  // namespace catgs::cuda::stages
