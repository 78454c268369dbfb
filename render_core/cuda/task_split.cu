// Load-aware task splitting (paper sec. 3.4, supplementary Alg. 1; mirrors cpu/task_split.cpp):
// the plan of rasterization tasks, built once per key frame and reused by its sub-frames (the
// sort cache holds the split tasks too).
//
// Two kernels and a scan: each tile works out its slice count n (and n partial slots when it is
// split), one 64-bit exclusive scan of (slots << 32 | n) numbers slices and partial slots tile by
// tile, and each tile writes its slices. No host round trip: the slice total stays on the device
// (rasterize_slices launches slice_capacity() blocks at a key frame).
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>

#include "cuda_check.h"
#include "task_split.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

__device__ __forceinline__ uint32_t slice_count(uint32_t load, uint64_t avg, bool split) {
  return (!split || load <= 2 * avg) ? 1u : static_cast<uint32_t>(load / avg);
}

__global__ void count_slices_kernel(const uint2* __restrict__ ranges,  // [tiles]
                                    uint32_t tiles, uint64_t avg, bool split,
                                    uint64_t* __restrict__ packed) {  // [tiles] (slots << 32 | slices)
  const uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  if (t >= tiles) return;
  const uint32_t n = slice_count(ranges[t].y - ranges[t].x, avg, split);
  packed[t] = (static_cast<uint64_t>(n > 1 ? n : 0u) << 32) | n;
}

__global__ void write_slices_kernel(const uint2* ranges,  // [tiles]
                                    uint32_t tiles, uint64_t avg, bool split,
                                    const uint64_t* first,  // [tiles] exclusive scan of packed
                                    SlicePlan plan) {
  const uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  if (t >= tiles) return;
  const uint2 r = ranges[t];
  const uint32_t load = r.y - r.x, n = slice_count(load, avg, split);
  const auto s0 = static_cast<uint32_t>(first[t]), slot0 = static_cast<uint32_t>(first[t] >> 32);
  plan.tile_plan[t] = make_uint4(s0, n, slot0, 0u);
  // n slices of avg entries, the first taking the remainder (so it is the largest, never tiny).
  const uint32_t head = n == 1 ? load : load - (n - 1) * static_cast<uint32_t>(avg);
  uint32_t at = r.x;
  for (uint32_t k = 0; k < n; ++k) {
    const uint32_t size = k == 0 ? head : static_cast<uint32_t>(avg);
    plan.slice_range[s0 + k] = make_uint2(at, at + size);
    plan.slice_tile[s0 + k] = make_uint2(t, k);
    at += size;
  }
  if (t + 1 == tiles) {
    plan.totals[0] = s0 + n;
    plan.totals[1] = slot0 + (n > 1 ? n : 0u);
  }
}

// Sort key of a slice: k in the high bits, then the complement of its length; unused slots last.
__global__ void slice_keys_kernel(SlicePlan plan, uint64_t capacity,
                                  uint32_t* keys,   // [capacity]
                                  uint32_t* ids) {  // [capacity]
  const uint64_t s = static_cast<uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (s >= capacity) return;
  const uint2 tk = plan.slice_tile[s];
  const uint2 r = plan.slice_range[s];
  keys[s] = tk.x == 0xffffffffu ? 0xffffffffu : slice_sort_key(tk.y, r.y - r.x);
  ids[s] = static_cast<uint32_t>(s);
}

}  // namespace

std::size_t order_slices_temp_bytes(uint64_t capacity) {
  std::size_t bytes = 0;
  CATGS_CUDA(cub::DeviceRadixSort::SortPairs(nullptr, bytes, static_cast<uint32_t*>(nullptr),
                                             static_cast<uint32_t*>(nullptr), static_cast<uint32_t*>(nullptr),
                                             static_cast<uint32_t*>(nullptr), static_cast<int64_t>(capacity)));
  return bytes;
}

void order_slices(const SlicePlan& plan, uint64_t capacity, uint32_t* scratch, uint32_t* order, void* temp,
                  std::size_t temp_bytes, cudaStream_t stream) {
  if (capacity == 0) return;
  uint32_t* keys = scratch;
  uint32_t* ids = scratch + capacity;
  uint32_t* sorted_keys = scratch + 2 * capacity;
  slice_keys_kernel<<<static_cast<unsigned>((capacity + 255) / 256), 256, 0, stream>>>(plan, capacity, keys, ids);
  CATGS_CUDA_LAUNCHED("slice_keys_kernel");
  CATGS_CUDA(cub::DeviceRadixSort::SortPairs(temp, temp_bytes, keys, sorted_keys, ids, order,
                                             static_cast<int64_t>(capacity), 0, 32, stream));
}

uint64_t split_average(uint32_t tiles, uint64_t entries, uint64_t min_slice) {
  return std::max<uint64_t>(min_slice, tiles > 0 ? std::max<uint64_t>(1, entries / tiles) : 1);
}

uint64_t slice_capacity(uint32_t tiles, uint64_t entries, uint64_t min_slice) {
  return tiles + entries / split_average(tiles, entries, min_slice);
}

std::size_t plan_slices_temp_bytes(uint32_t tiles) {
  std::size_t bytes = 0;
  CATGS_CUDA(cub::DeviceScan::ExclusiveSum(nullptr, bytes, static_cast<const uint64_t*>(nullptr),
                                           static_cast<uint64_t*>(nullptr), tiles));
  return bytes;
}

void plan_slices(const uint2* ranges, uint32_t tiles, uint64_t entries, bool split, uint64_t min_slice,
                 const SlicePlan& plan, uint64_t* scan_scratch, void* temp, std::size_t temp_bytes,
                 cudaStream_t stream) {
  const uint64_t avg = split_average(tiles, entries, min_slice), capacity = slice_capacity(tiles, entries, min_slice);
  // Slots past the total: empty range, no tile (their blocks return).
  CATGS_CUDA(cudaMemsetAsync(plan.slice_range, 0, capacity * sizeof(uint2), stream));
  CATGS_CUDA(cudaMemsetAsync(plan.slice_tile, 0xff, capacity * sizeof(uint2), stream));
  if (tiles == 0) return;
  uint64_t* packed = scan_scratch;
  uint64_t* first = scan_scratch + tiles;
  const unsigned blocks = (tiles + 255) / 256;
  count_slices_kernel<<<blocks, 256, 0, stream>>>(ranges, tiles, avg, split, packed);
  CATGS_CUDA_LAUNCHED("count_slices_kernel");
  CATGS_CUDA(cub::DeviceScan::ExclusiveSum(temp, temp_bytes, packed, first, tiles, stream));
  write_slices_kernel<<<blocks, 256, 0, stream>>>(ranges, tiles, avg, split, first, plan);
  CATGS_CUDA_LAUNCHED("write_slices_kernel");
}

}  // namespace catgs::cuda::stages
