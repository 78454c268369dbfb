// Load-aware task splitting (task_split.cu; mirrors cpu/task_split.cpp).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// Task splitting (task_split.cu; paper sec. 3.4, supplementary Alg. 1; mirrors cpu::plan_slices):
// with average load avg = max(1, L / tiles), a tile over 2 avg entries becomes load / avg slices
// of avg entries, the first taking the remainder; otherwise (or split = false) one slice.
// Slices are numbered tile by tile, a tile's in list order. Outputs:
//   slice_range [capacity] [begin, end) of each slice; slots past the total get [0, 0)
//   slice_tile  [capacity] (tile, k) of each slice; slots past the total get tile = 0xffffffff
//   tile_plan   [tiles]    (first slice, slice count, first partial slot, 0); a tile of one slice
//                          has no partial slots (its slice writes the image directly)
//   totals      [2]        (slices, partial slots), device
// capacity = slice_capacity(tiles, L, min_slice): tiles + L / avg bounds the slice count, with
// avg = split_average(tiles, L, min_slice) = max(L / tiles, 1, min_slice) the slice length
// (SpeculationParams::min_slice_entries).
//   saturated_from [tiles] reset by rasterize_slices: the first slice of a tile that saturates
//                          it alone (rasterize_slices.cu)
//   slot_finished  [slot_count] reset by rasterize_slices: 1 once the slice of that partial slot
//                          has written its partials (rasterize_slices.cu)
struct SlicePlan {
  uint2* slice_range;
  uint2* slice_tile;
  uint4* tile_plan;
  unsigned* totals;
  unsigned* saturated_from;
  unsigned* slot_finished;
  uint64_t slot_count;  // entries of slot_finished (at least the partial slots of any plan)
};
uint64_t split_average(uint32_t tiles, uint64_t entries, uint64_t min_slice);
uint64_t slice_capacity(uint32_t tiles, uint64_t entries, uint64_t min_slice);
std::size_t plan_slices_temp_bytes(uint32_t tiles);
void plan_slices(const uint2* ranges, uint32_t tiles, uint64_t entries, bool split, uint64_t min_slice,
                 const SlicePlan& plan, uint64_t* scan_scratch, void* temp, std::size_t temp_bytes,
                 cudaStream_t stream);

// The slice order's key (tune::kSliceLengthBits): index k in its tile, then the complement of
// its length; and the length back from a key (CudaRenderer::diagnostics: the heaviest slice).
__host__ __device__ inline uint32_t slice_sort_key(uint32_t k, uint32_t length) {
  const uint32_t kk = k < tune::kSliceIndexMax ? k : tune::kSliceIndexMax;
  const uint32_t len = length < tune::kSliceLengthMask ? length : tune::kSliceLengthMask;
  return (kk << tune::kSliceLengthBits) | (tune::kSliceLengthMask - len);
}
__host__ __device__ inline uint32_t slice_length_of_key(uint32_t key) {
  return tune::kSliceLengthMask - (key & tune::kSliceLengthMask);
}

// The slice order (task_split.cu): slices by k, then by decreasing length (a tile's first slice
// runs before its later ones, and the long ones start first); slots past the total last.
// scratch: [3 * capacity].
std::size_t order_slices_temp_bytes(uint64_t capacity);
void order_slices(const SlicePlan& plan, uint64_t capacity, uint32_t* scratch, uint32_t* order, void* temp,
                  std::size_t temp_bytes, cudaStream_t stream);

}  // namespace catgs::cuda::stages
