// A Gaussian's fields as the kernels read them, in either of DeviceScene's layouts (issue 74):
// the floats (and binary16 SH), or the compact codes decoded here by forward_model/compact_codes.h,
// the functions the compact scene's reader decodes the host model with, so both cores see the same
// floats. The layout is the scene's, the same for every thread: the branches never diverge.
#pragma once

#include <cuda_fp16.h>

#include "forward_model/compact_codes.h"
#include "forward_model/forward_model.h"
#include "records.h"

namespace catgs::cuda::stages {

__device__ __forceinline__ bool compact_layout(const SceneView& scene) { return scene.rotation_codes != nullptr; }

__device__ __forceinline__ const fm::ChunkRanges& ranges_of(const SceneView& scene, uint64_t i) {
  return scene.ranges[i / fm::kChunkSize];
}

// The opacity logit of Gaussian i.
__device__ __forceinline__ float opacity_logit_of(const SceneView& scene, uint64_t i) {
  return compact_layout(scene) ? scene.opacity_lut[scene.colour_codes[i].w] : scene.opacity_logits[i];
}

// The log scales [3] and rotation (w, x, y, z) [4] of Gaussian i.
__device__ __forceinline__ void log_scales_of(const SceneView& scene, uint64_t i, float out[3]) {
  if (compact_layout(scene)) {
    fm::compact_log_scales(scene.scale_codes[i], ranges_of(scene, i), out);
    return;
  }
  for (int a = 0; a < 3; ++a) out[a] = scene.log_scales[3 * i + a];
}
__device__ __forceinline__ void rotation_of(const SceneView& scene, uint64_t i, float out[4]) {
  if (compact_layout(scene)) {
    fm::compact_rotation(scene.rotation_codes[i], out);
    return;
  }
  for (int a = 0; a < 4; ++a) out[a] = scene.rotations[4 * i + a];
}

// The 3D covariance of Gaussian i (fm::covariance_3d of its log scales and rotation).
__device__ __forceinline__ fm::Cov3 covariance_of(const SceneView& scene, uint64_t i) {
  float s[3], q[4];
  log_scales_of(scene, i, s);
  rotation_of(scene, i, q);
  return fm::covariance_3d({s[0], s[1], s[2]}, {q[0], q[1], q[2], q[3]});
}

// A float rounded to binary16 and widened, as fm::half_bits rounds it (nearest even, saturating
// at +-65504; the compact decode is never NaN).
__device__ __forceinline__ float half_rounded(float v) {
  return __half2float(__float2half_rn(fminf(fmaxf(v, -65504.0f), 65504.0f)));
}

// The SH coefficients of Gaussian i as fm::sh_to_color_from reads them: binary16 in device memory
// (forward_model/sh_storage.h), or the compact codes decoded and rounded to binary16, exactly as
// the CPU reference's fm::HalfRoundedSh gives the host model's decoded floats.
struct SceneSh {
  const __half* sh;      // float layout: [K, 3] of this Gaussian
  const uint8_t* codes;  // compact layout: this Gaussian's SH rest codes
  uchar4 colour;         // compact layout: its DC codes
  const fm::ChunkRanges* r;
  __device__ __forceinline__ float operator()(int j) const {
    if (sh) return __half2float(sh[j]);
    const int k = j / 3, ch = j % 3;
    const float v = k == 0 ? fm::compact_dc(ch == 0   ? colour.x
                                            : ch == 1 ? colour.y
                                                      : colour.z,
                                            *r, ch)
                           : fm::compact_sh_rest(codes, j - 3, *r, k);
    return half_rounded(v);
  }
};
__device__ __forceinline__ SceneSh sh_of(const SceneView& scene, uint64_t i) {
  if (compact_layout(scene))
    return {nullptr, scene.sh_codes + static_cast<uint64_t>(scene.sh_code_bytes) * i, scene.colour_codes[i],
            &ranges_of(scene, i)};
  const uint64_t K = static_cast<uint64_t>(scene.sh_degree + 1) * static_cast<uint64_t>(scene.sh_degree + 1);
  return {scene.sh + K * 3 * i, nullptr, make_uchar4(0, 0, 0, 0), nullptr};
}

}  // namespace catgs::cuda::stages
