// Load-aware task splitting (paper sec. 3.4, supplementary Alg. 1; mirrors cpu/task_split.cpp):
// the plan of rasterization tasks and their order, built by every frame that rasterizes through
// slices (exact frames and catgs key frames) and reused by a key frame's sub-frames (the sort
// cache holds the split tasks too).
//
// One block of 1024 threads does it all (plan_slices_kernel). It replaced two kernels, a
// device-wide scan, two memsets and a CUB radix sort of the slices, whose launches cost more
// than the work (RESULTS.md, "Issue 19, fourth round").
#include <algorithm>

#include <cub/block/block_scan.cuh>

#include "cuda_check.h"
#include "load_bucket.cuh"
#include "task_split.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

constexpr int kPlanThreads = 1024;
// Later slices are ordered by their index k in the tile, 1 to kLevels - 1 (the last level holds
// every k from kLevels - 1 on).
constexpr uint32_t kLevels = 64;

__device__ __forceinline__ uint32_t slice_count(uint32_t load, uint64_t avg, bool split) {
  return (!split || load <= 2 * avg) ? 1u : static_cast<uint32_t>(load / avg);
}

// n slices of avg entries, the first taking the remainder (so it is the longest, never tiny).
__device__ __forceinline__ uint32_t first_slice_length(uint32_t load, uint32_t n, uint64_t avg) {
  return n == 1 ? load : load - (n - 1) * static_cast<uint32_t>(avg);
}

__device__ __forceinline__ uint32_t level_of(uint32_t k) { return k < kLevels ? k : kLevels - 1; }

// Two passes over the tiles, each thread taking tiles tid, tid + 1024, ... (coalesced): the
// first counts the first slices by length bucket and the later slices by index k, and thread 0
// turns the counts into where each group starts in the order (first slices from 0, the heaviest
// bucket first; later slices from `tiles`, k = 1 first); the second numbers the slices and
// partial slots tile by tile, 1024 tiles a round (a block scan, plus the rounds before), and
// writes each tile's plan and slices and places them in the order. Within a group the order is
// whatever the shared-memory atomics give: it moves only the kernel's tail, never the image.
__global__ void __launch_bounds__(kPlanThreads)
    plan_slices_kernel(const uint2* __restrict__ ranges,  // [tiles]
                       uint32_t tiles, uint64_t avg, bool split, uint64_t capacity, SlicePlan plan,
                       uint32_t* __restrict__ order,      // [capacity]
                       uint32_t* __restrict__ longest) {  // [1]
  using Scan = cub::BlockScan<unsigned long long, kPlanThreads>;
  __shared__ typename Scan::TempStorage scan_temp;
  __shared__ unsigned count[kLoadBuckets], next[kLoadBuckets], level_count[kLevels], level_next[kLevels], most;
  __shared__ unsigned long long before;  // (slots << 32 | slices) of the rounds before
  for (auto b = threadIdx.x; b < kLoadBuckets; b += kPlanThreads) count[b] = 0;
  for (auto k = threadIdx.x; k < kLevels; k += kPlanThreads) level_count[k] = 0;
  if (threadIdx.x == 0) {
    most = 0;
    before = 0;
  }
  __syncthreads();

  for (uint32_t t = threadIdx.x; t < tiles; t += kPlanThreads) {
    const uint32_t load = ranges[t].y - ranges[t].x, n = slice_count(load, avg, split);
    const uint32_t head = first_slice_length(load, n, avg);
    atomicAdd(&count[load_bucket(head)], 1u);
    atomicMax(&most, head);
    for (uint32_t k = 1; k < n && k < kLevels - 1; ++k) atomicAdd(&level_count[k], 1u);
    if (n > kLevels - 1) atomicAdd(&level_count[kLevels - 1], n - (kLevels - 1));
  }
  __syncthreads();
  if (threadIdx.x == 0) {
    buckets_from_heaviest(count, next);
    *longest = most;
    unsigned at = tiles;
    for (uint32_t k = 1; k < kLevels; ++k) {
      level_next[k] = at;
      at += level_count[k];
    }
  }
  __syncthreads();

  for (uint32_t round = 0; round < tiles; round += kPlanThreads) {
    const uint32_t t = round + threadIdx.x;
    const uint2 r = t < tiles ? ranges[t] : make_uint2(0u, 0u);
    const uint32_t load = r.y - r.x, n = t < tiles ? slice_count(load, avg, split) : 0u;
    unsigned long long first = 0, in_round = 0;
    Scan(scan_temp).ExclusiveSum((static_cast<unsigned long long>(n > 1 ? n : 0u) << 32) | n, first, in_round);
    first += before;
    __syncthreads();  // every thread has read `before`
    if (threadIdx.x == 0) before += in_round;
    if (t < tiles) {
      const auto s = static_cast<uint32_t>(first), slot = static_cast<uint32_t>(first >> 32);
      const uint32_t head = first_slice_length(load, n, avg);
      plan.tile_plan[t] = make_uint4(s, n, slot, 0u);
      uint32_t at = r.x;
      for (uint32_t k = 0; k < n; ++k) {
        const uint32_t size = k == 0 ? head : static_cast<uint32_t>(avg);
        plan.slice_range[s + k] = make_uint2(at, at + size);
        plan.slice_tile[s + k] = make_uint2(t, k);
        at += size;
        order[atomicAdd(k == 0 ? &next[load_bucket(head)] : &level_next[level_of(k)], 1u)] = s + k;
      }
    }
    __syncthreads();  // `before` updated, scan_temp free
  }
  const auto total = static_cast<unsigned>(before);
  if (threadIdx.x == 0) {
    plan.totals[0] = total;
    plan.totals[1] = static_cast<unsigned>(before >> 32);
  }
  for (uint64_t i = total + threadIdx.x; i < capacity; i += kPlanThreads) order[i] = kNoSlice;
}

}  // namespace

uint64_t split_average(uint32_t tiles, uint64_t entries, uint64_t min_slice) {
  return std::max<uint64_t>(min_slice, tiles > 0 ? std::max<uint64_t>(1, entries / tiles) : 1);
}

uint64_t slice_capacity(uint32_t tiles, uint64_t entries, uint64_t min_slice) {
  return tiles + entries / split_average(tiles, entries, min_slice);
}

void plan_slices(const uint2* ranges, uint32_t tiles, uint64_t entries, bool split, uint64_t min_slice,
                 const SlicePlan& plan, uint32_t* order, uint32_t* longest, cudaStream_t stream) {
  const uint64_t avg = split_average(tiles, entries, min_slice), capacity = slice_capacity(tiles, entries, min_slice);
  plan_slices_kernel<<<1, kPlanThreads, 0, stream>>>(ranges, tiles, avg, split, capacity, plan, order, longest);
  CATGS_CUDA_LAUNCHED("plan_slices_kernel");
}

}  // namespace catgs::cuda::stages
