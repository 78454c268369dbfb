// Stage 2a of a frame sized ahead: its key packing, slice length and redo flags, and the
// sentinel keys past its list (list_plan.h).
#include <algorithm>

#include "base/cuda_check.h"
#include "list_plan.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

__global__ void plan_list_kernel(const unsigned long long* __restrict__ entries,
                                 const unsigned long long* __restrict__ depth_low_complement,
                                 const unsigned long long* __restrict__ depth_high, const unsigned* __restrict__ kept,
                                 uint64_t capacity, uint64_t slot_chunks, uint32_t tiles, uint64_t min_slice,
                                 ListPlan* __restrict__ plan) {
  const uint64_t length = *entries;
  bool fits = true;
  // As count_render_list reads them: the low end complemented, both as the float bits' 32 bits.
  const auto low = ~static_cast<uint32_t>(*depth_low_complement);
  const auto high = static_cast<uint32_t>(*depth_high);
  ListPlan p;
  p.packing = fm::room_packing(low, high, tiles, &fits);
  // split_average (task_split.cu), of this frame's own length.
  const uint64_t per_tile = tiles > 0 ? (length / tiles > 1 ? length / tiles : 1) : 1;
  p.avg = per_tile > min_slice ? per_tile : min_slice;
  p.redo =
      (length > capacity ? kListLonger : 0u) | (*kept > slot_chunks ? kChunksMore : 0u) | (fits ? 0u : kDepthRangeWide);
  *plan = p;
}

__global__ void __launch_bounds__(tune::kEntryThreads)
    pad_list_kernel(uint32_t* __restrict__ keys, const unsigned long long* __restrict__ entries, uint64_t capacity) {
  const uint64_t stride = static_cast<uint64_t>(gridDim.x) * blockDim.x;
  for (uint64_t i = *entries + static_cast<uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x; i < capacity; i += stride)
    keys[i] = 0xffffffffu;
}

}  // namespace

void plan_list(const unsigned long long* entries, const unsigned long long* depth_low_complement,
               const unsigned long long* depth_high, const unsigned* kept, uint64_t capacity, uint64_t slot_chunks,
               uint32_t tiles, uint64_t min_slice, ListPlan* plan, cudaStream_t stream) {
  plan_list_kernel<<<1, 1, 0, stream>>>(entries, depth_low_complement, depth_high, kept, capacity, slot_chunks, tiles,
                                        min_slice, plan);
  CATGS_CUDA_LAUNCHED("plan_list_kernel");
}

void pad_list(uint32_t* keys, const unsigned long long* entries, uint64_t capacity, cudaStream_t stream) {
  if (capacity == 0) return;
  // The padding is a small share of the capacity (the headroom), so a few blocks stride it.
  const uint64_t want = (capacity / 8 + tune::kEntryThreads - 1) / tune::kEntryThreads;
  const auto blocks = static_cast<unsigned>(std::clamp<uint64_t>(want, 1, tune::kMaxEntryBlocks));
  pad_list_kernel<<<blocks, tune::kEntryThreads, 0, stream>>>(keys, entries, capacity);
  CATGS_CUDA_LAUNCHED("pad_list_kernel");
}

}  // namespace catgs::cuda::stages
