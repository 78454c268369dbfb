// How the pre-processing kernels (preprocess.cu, speculative_preprocess.cu, subframe_features.cu)
// write a Gaussian's stages::Splat, the rasterizers' 32-byte record (stages.h).
#pragma once

#include <cmath>

#include "forward_model/forward_model.h"
#include "records.h"
#include "scene_fields.cuh"  // sh_of and the other fields, in either layout

namespace catgs::cuda::stages {

// The splat of a Gaussian with 2D mean `mean` (pixels), conic (A, B, C) and `opacity` in (0, 1],
// whose q_max = fm::opacity_aware_qmax(opacity) the caller has worked out (every caller needs it
// for its own tests), and log2(opacity), which the rasterizers add to the exponent instead of
// multiplying alpha by the opacity (blend.cuh blend_entry): one log2f per Gaussian instead of a
// multiply per entry and pixel.
__device__ __forceinline__ Splat make_splat(glm::vec2 mean, glm::vec3 conic, float opacity, float q_max) {
  return {make_float4(mean.x, mean.y, conic.x, conic.y), make_float4(conic.z, opacity, q_max, log2f(opacity))};
}

// A Gaussian culled at a sub-frame's pose: opacity 0, q_max -inf (no quadratic is below it) and
// log2(opacity) -inf (alpha 0 at every pixel), as make_splat gives at opacity 0.
__device__ __forceinline__ Splat culled_splat() {
  return {make_float4(0.0f, 0.0f, 0.0f, 0.0f), make_float4(0.0f, 0.0f, -INFINITY, -INFINITY)};
}

}  // namespace catgs::cuda::stages
