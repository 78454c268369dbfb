// catgs sub-frames (subframe_features.cu; mirrors cpu/subframe_features.cpp).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// Frustum cache (subframe_features.cu; paper sec. 3.2): the slots of the Gaussians with entries
// (records.h listed_tiles) among the n slots, increasing, into cached[]; their number into *count
// (device).
std::size_t select_cached_temp_bytes(uint64_t n);
void select_cached(const uint32_t* tiles_touched, const uint32_t* chunk_total, uint64_t n, uint32_t* cached,
                   unsigned* count, void* temp, std::size_t temp_bytes, cudaStream_t stream);

// catgs sub-frame, stage 1 (subframe_features.cu; mirrors cpu::update_subframe_features):
// recomputes the splat (mean, conic, opacity: 0 when culled here) and colour (unless
// `key_colour`: the key frame's is kept) of the `count` cached Gaussians at `cam`, and sets
// *outside = 1 when an on-screen ellipse reaches a tile its trail was not listed in (the frame
// must then be a key frame). *outside must hold 0 on entry.
// `live`: the key frame's kept chunks (LiveChunks::index), which map a slot to its Gaussian.
void update_subframe_features(const SceneView& scene, const CameraParams& cam, const uint32_t* cached, uint32_t count,
                              const uint32_t* live, bool key_colour, const Projected& projected, const Trails& trails,
                              unsigned* outside, cudaStream_t stream);

// catgs sub-frame (subframe_features.cu; mirrors cpu::unlisted_reach_image): sets *outside = 1
// when a Gaussian the key frame did not list (its chunk not in the key frame's `live`, or its
// slot's records.h listed_tiles 0) reaches a pixel at `cam`: it is outside the frustum cache, so
// only a key frame can draw it. Chunks outside the view at `cam` (fm::chunk_outside_view) are
// skipped whole, and so are chunks outside the LOD cut at the group's key camera `key` (records.h
// lod_drawn).
void check_unlisted(const SceneView& scene, const CameraParams& cam, const CameraParams& key,
                    const uint32_t* tiles_touched, const uint32_t* chunk_total, const LiveChunks& live,
                    unsigned* outside, cudaStream_t stream);

}  // namespace catgs::cuda::stages
