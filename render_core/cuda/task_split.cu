// Load-aware task splitting (paper sec. 3.4, supplementary Alg. 1; mirrors cpu/task_split.cpp):
// the plan of rasterization tasks and their order, built by every frame that rasterizes through
// slices (exact frames and catgs key frames) and reused by a key frame's sub-frames (the sort
// cache holds the split tasks too).
//
// Two launches of a block per 1024 tiles (plan_count_kernel, plan_place_kernel): they replaced
// one block of 1024 threads that walked every tile twice (25-37 us at 1080p, ncu), which had
// replaced two kernels, a device-wide scan, two memsets and a CUB radix sort of the slices,
// whose launches cost more than the work (docs/history/render_core_task_split.md, "Exact frames
// split heavy tiles; a one-block split plan; ..." and "The split plan in two wide launches").
#include <algorithm>

#include <cub/block/block_reduce.cuh>
#include <cub/block/block_scan.cuh>

#include "base/cuda_check.h"
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

// The order's groups: first slices by length bucket, heaviest first (group kLoadBuckets - 1 - b
// for bucket b), then later slices by level k = 1 .. kLevels - 1 (group kLoadBuckets + k - 1).
// The first slices number `tiles`, so the later ones start there.
constexpr int kGroups = kLoadBuckets + static_cast<int>(kLevels) - 1;

__device__ __forceinline__ int first_group(uint32_t head) { return kLoadBuckets - 1 - load_bucket(head); }
__device__ __forceinline__ int later_group(uint32_t k) { return kLoadBuckets + static_cast<int>(level_of(k)) - 1; }

// Per-block results of the counting pass, in the plan's scratch (plan_scratch_bytes).
struct PlanScratch {
  unsigned* group_count;            // [blocks, kGroups] slices of each group in the block's tiles
  unsigned long long* block_total;  // [blocks] (partial slots << 32 | slices) of the block's tiles
  unsigned* block_longest;          // [blocks] the longest first slice in the block's tiles
};

__host__ __device__ inline PlanScratch plan_scratch(void* base, uint32_t blocks) {
  auto* totals = static_cast<unsigned long long*>(base);
  auto* counts = reinterpret_cast<unsigned*>(totals + blocks);
  return {counts, totals, counts + static_cast<uint64_t>(blocks) * kGroups};
}

__host__ __device__ inline uint32_t plan_blocks(uint32_t tiles) {
  return tiles == 0 ? 1u : (tiles + kPlanThreads - 1) / kPlanThreads;
}

// A tile's slices as (partial slots << 32 | slices): a split tile has a slot per slice.
__device__ __forceinline__ unsigned long long slices_and_slots(uint32_t n) {
  return (static_cast<unsigned long long>(n > 1 ? n : 0u) << 32) | n;
}

// Pass 1, a block per 1024 tiles: counts the block's slices by group (shared-memory atomics),
// its slices and slots (a block reduction) and its longest first slice.
__global__ void __launch_bounds__(kPlanThreads)
    plan_count_kernel(const uint2* __restrict__ ranges,  // [tiles]
                      uint32_t tiles, uint32_t first_tile, uint32_t end_tile, uint64_t avg, bool split,
                      PlanScratch scratch) {
  using Reduce = cub::BlockReduce<unsigned long long, kPlanThreads>;
  __shared__ typename Reduce::TempStorage reduce_temp;
  __shared__ unsigned count[kGroups], most;
  for (auto g = threadIdx.x; g < kGroups; g += kPlanThreads) count[g] = 0;
  if (threadIdx.x == 0) most = 0;
  __syncthreads();
  const uint32_t t = blockIdx.x * kPlanThreads + threadIdx.x;
  uint32_t n = 0;
  if (t < tiles && t >= first_tile && t < end_tile) {  // a pass plans its own tiles only
    const uint32_t load = ranges[t].y - ranges[t].x;
    n = slice_count(load, avg, split);
    const uint32_t head = first_slice_length(load, n, avg);
    atomicAdd(&count[first_group(head)], 1u);
    atomicMax(&most, head);
    for (uint32_t k = 1; k < n && k < kLevels - 1; ++k) atomicAdd(&count[later_group(k)], 1u);
    if (n > kLevels - 1) atomicAdd(&count[later_group(kLevels - 1)], n - (kLevels - 1));
  }
  const unsigned long long total = Reduce(reduce_temp).Sum(slices_and_slots(n));
  __syncthreads();
  for (auto g = threadIdx.x; g < kGroups; g += kPlanThreads)
    scratch.group_count[static_cast<uint64_t>(blockIdx.x) * kGroups + g] = count[g];
  if (threadIdx.x == 0) {
    scratch.block_total[blockIdx.x] = total;
    scratch.block_longest[blockIdx.x] = most;
  }
}

// Pass 2, the same blocks: each works out where each group starts in the order (an exclusive
// scan of the groups' totals over every block) and where its own tiles' share of each group and
// of the slices and slots starts (the blocks before it), then numbers its tiles' slices and
// slots (a block scan), writes their plan and places them in the order. Within a block's share
// of a group the order is whatever the shared-memory atomics give: it moves only the
// rasterizer's tail, never the image. Block 0 writes the totals and the longest slice; every
// block fills part of the order past the total with kNoSlice.
__global__ void __launch_bounds__(kPlanThreads)
    plan_place_kernel(const uint2* __restrict__ ranges,  // [tiles]
                      uint32_t tiles, uint32_t first_tile, uint32_t end_tile, uint64_t avg, bool split,
                      uint64_t capacity, SlicePlan plan, PlanScratch scratch,
                      uint32_t* __restrict__ order,      // [capacity]
                      uint32_t* __restrict__ longest) {  // [1]
  using Scan = cub::BlockScan<unsigned long long, kPlanThreads>;
  __shared__ typename Scan::TempStorage scan_temp;
  __shared__ unsigned next[kGroups];
  __shared__ unsigned long long before, total;
  const uint32_t blocks = gridDim.x, b = blockIdx.x;
  unsigned in_group = 0, mine = 0;  // group threadIdx.x: over every block, over the blocks before b
  if (threadIdx.x < kGroups) {
    for (uint32_t i = 0; i < blocks; ++i) {
      const unsigned c = scratch.group_count[static_cast<uint64_t>(i) * kGroups + threadIdx.x];
      in_group += c;
      mine += i < b ? c : 0u;
    }
  }
  unsigned long long start = 0;
  Scan(scan_temp).ExclusiveSum(static_cast<unsigned long long>(in_group), start);
  if (threadIdx.x < kGroups) next[threadIdx.x] = static_cast<unsigned>(start) + mine;
  if (threadIdx.x == 0) {
    unsigned long long sum = 0, prefix = 0;
    unsigned most = 0;
    for (uint32_t i = 0; i < blocks; ++i) {
      prefix += i < b ? scratch.block_total[i] : 0ull;
      sum += scratch.block_total[i];
      most = max(most, scratch.block_longest[i]);
    }
    before = prefix;
    total = sum;
    if (b == 0) {
      plan.totals[0] = static_cast<unsigned>(sum);
      plan.totals[1] = static_cast<unsigned>(sum >> 32);
      *longest = most;
    }
  }
  __syncthreads();  // next, before and total written; scan_temp free

  const uint32_t t = b * kPlanThreads + threadIdx.x;
  const uint2 r = t < tiles ? ranges[t] : make_uint2(0u, 0u);
  const bool planned = t < tiles && t >= first_tile && t < end_tile;
  const uint32_t load = r.y - r.x, n = planned ? slice_count(load, avg, split) : 0u;
  unsigned long long first = 0;
  Scan(scan_temp).ExclusiveSum(slices_and_slots(n), first);
  first += before;
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
      order[atomicAdd(&next[k == 0 ? first_group(head) : later_group(k)], 1u)] = s + k;
    }
  }
  const auto slices = static_cast<uint32_t>(total);
  for (uint64_t i = slices + static_cast<uint64_t>(t); i < capacity; i += static_cast<uint64_t>(blocks) * kPlanThreads)
    order[i] = kNoSlice;
}

}  // namespace

uint64_t split_average(uint32_t tiles, uint64_t entries, uint64_t min_slice) {
  return std::max<uint64_t>(min_slice, tiles > 0 ? std::max<uint64_t>(1, entries / tiles) : 1);
}

uint64_t slice_capacity(uint32_t tiles, uint64_t entries, uint64_t min_slice) {
  return tiles + entries / split_average(tiles, entries, min_slice);
}

std::size_t plan_scratch_bytes(uint32_t tiles) {
  const uint64_t blocks = plan_blocks(tiles);
  return blocks * (sizeof(unsigned long long) + (kGroups + 1) * sizeof(unsigned));
}

void plan_slices(const uint2* ranges, uint32_t tiles, uint64_t avg, uint64_t capacity, bool split,
                 const SlicePlan& plan, void* scratch, uint32_t* order, uint32_t* longest, cudaStream_t stream,
                 uint32_t first_tile, uint32_t end_tile) {
  const uint32_t blocks = plan_blocks(tiles);
  const PlanScratch s = plan_scratch(scratch, blocks);
  plan_count_kernel<<<blocks, kPlanThreads, 0, stream>>>(ranges, tiles, first_tile, end_tile, avg, split, s);
  CATGS_CUDA_LAUNCHED("plan_count_kernel");
  plan_place_kernel<<<blocks, kPlanThreads, 0, stream>>>(ranges, tiles, first_tile, end_tile, avg, split, capacity,
                                                         plan, s, order, longest);
  CATGS_CUDA_LAUNCHED("plan_place_kernel");
}

}  // namespace catgs::cuda::stages
