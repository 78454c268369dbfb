// Stage 2a of a frame sized ahead (list_plan.cu): what a frame that does not read its counts back
// mid-frame decides on the device (CudaRenderer's sized-ahead frames, docs/DESIGN.md "A frame
// sized ahead"). Raw device pointers and an explicit stream; every launcher checks its launch
// (CudaError).
//
// A frame counted first reads its list length, depth range and kept chunks back to the host
// before it emits (the frame's one host-device sync; cuda_renderer.cpp count_render_list). A
// frame sized ahead instead gives its list a capacity from the frames before it, sorts that many
// keys (the slots past the list hold the sentinel key, which sorts last and which the tile
// ranges skip), and leaves these to the device; the host reads them with the frame's planes and
// draws the frame again, counted first, when the list did not fit.
#pragma once

#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// Why a frame sized ahead must be drawn again (ListPlan::redo, bits).
enum ListRedo : uint32_t {
  kListLonger = 1u,      // the list has more entries than the capacity
  kChunksMore = 2u,      // pre-processing kept more chunks than the slots hold
  kDepthRangeWide = 4u,  // the listed depths need the plain 64-bit key (key_packing.h)
};

// The device's decisions for one frame (device memory, written by plan_list).
struct ListPlan {
  DepthKeyPacking packing;  // fm::room_packing of the listed depths: the 32-bit key
  uint64_t avg;             // the slice length, split_average(tiles, entries, min_slice)
  uint32_t redo;            // ListRedo bits; 0: the frame is good
};

// One thread: reads the list length (*entries), the listed depths' range (the complemented low
// end and the high end, float bits; CudaRenderer's counter slots) and the chunks pre-processing
// kept (*kept), and writes *plan for a list of `capacity` slots and `slot_chunks` slot chunks on a
// grid of `tiles` tiles.
void plan_list(const unsigned long long* entries, const unsigned long long* depth_low_complement,
               const unsigned long long* depth_high, const unsigned* kept, uint64_t capacity, uint64_t slot_chunks,
               uint32_t tiles, uint64_t min_slice, ListPlan* plan, cudaStream_t stream);

// The sentinel key 0xffffffff into keys[*entries, capacity): the slots the list leaves, so that a
// sort of `capacity` keys puts them last.
void pad_list(uint32_t* keys, const unsigned long long* entries, uint64_t capacity, cudaStream_t stream);

}  // namespace catgs::cuda::stages
