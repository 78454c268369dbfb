// catgs key frames, stage 1 (speculative_preprocess.cu; mirrors cpu/speculative_preprocess.cpp).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// catgs key frame, stage 1 (speculative_preprocess.cu; mirrors cpu/speculative_preprocess.cpp):
// each Gaussian is projected at every camera of `path`; one visible at the key camera gets the
// key frame's features, a trail (fm::build_trail, widened by `widening`) and the number of
// tiles the trail touches. Big trails are counted by count_big_tiles (called here). A Gaussian
// beyond one same image edge at every camera of the path is culled before any 2D covariance
// (as cpu::speculative_preprocess). Whole chunks are culled first (fm::chunk_misses_path, a
// thread per chunk): the kept ones go to `live` (count zero on entry), a culled one gets
// chunk_total = 0 and leaves its Gaussians' tiles_touched unwritten (records.h listed_tiles).
void speculative_preprocess(const SceneView& scene, const PathParams& path, const TrailWidening& widening,
                            const Projected& out, const Trails& trails, const LiveChunks& live,
                            unsigned long long* visible, const BigList& big, cudaStream_t stream);

// catgs planner input (speculative_preprocess.cu; mirrors cpu::max_screen_motion): the largest
// screen motion (pixels) between cameras a and b of the means visible in a deeper than
// min_depth, as float bits into *max_bits (which must hold 0 on entry; atomicMax on the bits of
// non-negative floats orders like the floats). Reads only the chunks whose means may count
// (fm::chunk_means_off_image), so its cost follows the key view, not the scene's size.
void max_screen_motion(const SceneView& scene, const CameraParams& a, const CameraParams& b, float min_depth,
                       unsigned* max_bits, cudaStream_t stream);

}  // namespace catgs::cuda::stages
