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
// Slices are numbered tile by tile, a tile's in list order. The plan:
//   slice_range [capacity] [begin, end) of each slice (the first `total` are written)
//   slice_tile  [capacity] (tile, k) of each slice (likewise)
//   tile_plan   [tiles]    (first slice, slice count, first partial slot, 0); a tile of one slice
//                          has no partial slots (its slice writes the image directly)
//   totals      [2]        (slices, partial slots), device
// capacity = slice_capacity(tiles, L, min_slice): tiles + L / avg bounds the slice count, with
// avg = split_average(tiles, L, min_slice) = max(L / tiles, 1, min_slice) the slice length
// (SpeculationParams::min_slice_entries).
// The rasterizer's per-tile state (rasterize_slices.cu), set to these values once, when the
// buffers are allocated, and left so by every rasterize_slices launch:
//   saturated_from [tiles] all ones: the first slice of a tile that saturates it alone
//   slices_done    [tiles] 0: the tile's slices that have finished (the last one merges)
//   slot_finished  [slots] 0: 1 once the slice of that partial slot has written its partials
struct SlicePlan {
  uint2* slice_range;
  uint2* slice_tile;
  uint4* tile_plan;
  unsigned* totals;
  unsigned* saturated_from;
  unsigned* slices_done;
  unsigned* slot_finished;
};
uint64_t split_average(uint32_t tiles, uint64_t entries, uint64_t min_slice);
uint64_t slice_capacity(uint32_t tiles, uint64_t entries, uint64_t min_slice);
// A pass of a frame drawn in passes (renderer/render_passes.h): its slice length is the whole
// frame's, avg = split_average(tiles, frame entries, min_slice), so its tiles split as in one pass;
// its `entries` entries make at most tiles + entries / avg slices.
inline uint64_t pass_slice_capacity(uint32_t tiles, uint64_t entries, uint64_t avg) { return tiles + entries / avg; }

// order[] past the slice total (its blocks return at once).
inline constexpr uint32_t kNoSlice = 0xffffffffu;

// The plan and the order the rasterizer's blocks take its slices in, from the tile ranges, in
// two launches of a block per 1024 tiles (no host round trip: the slice total stays on the
// device and a frame launches `capacity` blocks); scratch: plan_scratch_bytes(tiles) of device
// memory. order [capacity]: first every tile's first slice (k = 0), longest
// first to within a quarter of an octave (load_bucket.cuh), so the heavy work starts early and
// the light tiles fill in behind it; then the later slices (k >= 1, all avg long) tile by tile,
// so a split tile's first slice has usually finished, and told its later ones which pixels it
// ended, before they start (rasterize_slices.cu); kNoSlice past the total. *longest: the longest
// slice's entries (CudaRenderer::diagnostics).
// `avg`: the slice length (split_average; a pass's, its frame's), `capacity`: the order's length
// (slice_capacity, or pass_slice_capacity for a pass). Only tiles [first_tile, end_tile) get
// slices (a pass's region: the other tiles keep the other passes' pixels); the rest none.
std::size_t plan_scratch_bytes(uint32_t tiles);
void plan_slices(const uint2* ranges, uint32_t tiles, uint64_t avg, uint64_t capacity, bool split,
                 const SlicePlan& plan, void* scratch, uint32_t* order, uint32_t* longest, cudaStream_t stream,
                 uint32_t first_tile = 0, uint32_t end_tile = 0xffffffffu);

}  // namespace catgs::cuda::stages
