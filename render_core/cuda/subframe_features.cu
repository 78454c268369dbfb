// catgs sub-frames (paper sec. 3.2): the frustum cache (the Gaussians the key frame listed) and
// their per-Gaussian features at the sub-frame's own pose, with the check that each on-screen
// ellipse still lies inside the trail the key frame listed it by (mirrors
// cpu/subframe_features.cpp). Built with -fmad=false: the containment check decides key vs
// sub-frame, and should decide as the CPU reference does.
#include <cub/device/device_select.cuh>
#include <thrust/iterator/counting_iterator.h>

#include "forward_model/trail.h"
#include "base/cuda_check.h"
#include "splat.cuh"
#include "subframe_features.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

struct Listed {
  const uint32_t* tiles_touched;  // [S]
  const uint32_t* chunk_total;    // [SC] (listed_tiles)
  __device__ bool operator()(uint32_t i) const { return listed_tiles(tiles_touched, chunk_total, i) > 0; }
};

// One thread per cached Gaussian. A Gaussian culled at this pose gets zero conic and opacity
// (every pixel then skips it): behind the camera, degenerate, or reaching no pixel centre of
// the frame even at q_max + kExactQMargin, the widest level any raster test uses. The last
// skips its colour and trail reads (the kernel is bound by DRAM: ncu, 2.7 TB/s on a city
// bicycle sub-frame). Only an ellipse that reaches a pixel must lie inside its trail. At most
// 64 registers (4 blocks of 256 per SM): the cull took it to 72, and 3 blocks per SM made the
// kernel slower than before the cull (tunables.h kSubframeFeaturesMinBlocks).
__global__ void __launch_bounds__(tune::kGaussianThreads, tune::kSubframeFeaturesMinBlocks)
    subframe_features_kernel(SceneView scene, CameraParams cam,
                             const uint32_t* cached,  // [count] slots
                             uint32_t count,
                             const uint32_t* live,  // [slot chunks] the key frame's kept chunks
                             bool key_colour, Projected out, Trails trails,
                             unsigned* outside) {  // [1]
  const uint32_t c = blockIdx.x * blockDim.x + threadIdx.x;
  if (c >= count) return;
  // Once some Gaussian has left its trail the frame is drawn again as a key frame, which
  // recomputes every feature: the blocks that start after that have nothing useful to do. Read
  // through volatile (other blocks of this kernel write it); no barrier or warp collective
  // follows, so threads may disagree. On the fast real paths many sub-frame attempts fail
  // (docs/history/render_core_profiles.md, "A speculative key frame on the city (after b016ea2)").
  if (*static_cast<volatile unsigned*>(outside) != 0u) return;
  const uint32_t slot = cached[c];
  // The slot's Gaussian: the key frame's k-th kept chunk's (records.h Projected).
  const uint64_t g = static_cast<uint64_t>(live[slot / fm::kChunkSize]) * fm::kChunkSize + slot % fm::kChunkSize;
  const glm::vec3 mean(scene.means[3 * g], scene.means[3 * g + 1], scene.means[3 * g + 2]);
  const glm::vec3 p = cam.R * mean + cam.t;
  const Splat culled = culled_splat();
  if (!(p.z > cam.near_plane) || p.z > cam.far_plane) {
    out.splat[slot] = culled;
    return;
  }
  const fm::Cov3 cov3 = covariance_of(scene, g);
  const glm::vec3 cov2 = fm::covariance_2d(cov3, cam.R, p, cam.fx, cam.fy, cam.tan_half_fov);
  glm::vec3 conic;
  if (!fm::conic_from_cov2d(cov2, &conic)) {
    out.splat[slot] = culled;
    return;
  }
  const glm::vec2 mean2d(cam.fx * p.x / p.z + cam.cx - 0.5f, cam.fy * p.y / p.z + cam.cy - 0.5f);
  // The key frame's q_max (the opacity does not change), worked out again rather than read back.
  const float opacity = fm::sigmoid(opacity_logit_of(scene, g));
  const float q_max = fm::opacity_aware_qmax(opacity);
  if (fm::tile_count(fm::ellipse_tile_rect(mean2d, cov2, q_max + fm::kExactQMargin, cam.width, cam.height)) == 0) {
    out.splat[slot] = culled;
    return;
  }
  const bool on_screen = fm::tile_count(fm::ellipse_tile_rect(mean2d, cov2, q_max, cam.width, cam.height)) > 0;
  if (on_screen) {
    // The trail's conic is read only when the cheap containment test fails (the kernel is bound
    // by DRAM): q_trail rides in the covariance's spare lane.
    const float4 mm = trails.mean0_motion[slot], tc = trails.cov[slot];
    const glm::vec2 mean0(mm.x, mm.y), motion(mm.z, mm.w);
    if (!fm::trail_contains(mean0, motion, glm::vec3(tc.x, tc.y, tc.z), tc.w, mean2d, cov2, q_max)) {
      const float4 cq = trails.conic_q[slot];
      if (!fm::listed_tiles_cover(mean0, motion, glm::vec3(cq.x, cq.y, cq.z), tc.w, mean2d, cov2, conic, q_max,
                                  cam.width, cam.height))
        *outside = 1u;  // any writer will do: one flag for the frame
    }
  }
  // Drawn at this pose (fm::drawn_opacity; q_max stays the undrawn opacity's, no smaller).
  const float drawn = fm::drawn_opacity(opacity, cov2, fm::lod_chunk_merged(scene.lod, g / fm::kChunkSize));
  out.splat[slot] = make_splat(mean2d, conic, drawn, q_max);
  if (key_colour) return;  // the key frame's colour stays (SpeculationParams::subframe_key_colour)
  const glm::vec3 col = fm::sh_to_color_from(scene.sh_degree, sh_of(scene, g), glm::normalize(mean - cam.position));
  out.color[slot] = make_float4(col.x, col.y, col.z, 0.0f);
}

// A warp per chunk (grid-stride over the scene's chunks; a chunk the key frame kept read at its
// slot chunk): a Gaussian the key frame did not list that reaches a pixel at this pose raises the
// flag (fm::unlisted_reaches_image; most return after reading
// tiles_touched or after the cheap bound). A chunk outside the view at this pose
// (fm::chunk_outside_view, every lane works it out: no shared memory, no barrier) holds no such
// Gaussian and is skipped without reading its Gaussians, and so is a chunk outside the key
// frame's LOD cut (lod_drawn at `key`): another level draws it.
__global__ void __launch_bounds__(tune::kGaussianThreads)
    unlisted_kernel(SceneView scene, CameraParams cam, CameraParams key,
                    const uint32_t* tiles_touched,  // [S] of the key frame
                    const uint32_t* chunk_total,    // [SC] of the key frame
                    LiveChunks live,                // the key frame's kept chunks
                    unsigned* outside) {            // [1]
  // Already raised by the features kernel (queued before): the frame re-keys, nothing to add.
  if (*outside) return;
  const uint64_t chunks = fm::chunk_count(scene.n);
  const uint64_t warps = static_cast<uint64_t>(gridDim.x) * (blockDim.x / 32u);
  const uint64_t lane = threadIdx.x & 31u;
  for (uint64_t c = (static_cast<uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x) / 32u; c < chunks; c += warps) {
    if (!lod_drawn(scene, c, key) || fm::chunk_outside_view(scene.chunks[c], cam)) continue;  // warp-uniform
    const uint64_t end = min(scene.n, (c + 1) * fm::kChunkSize);
    const bool kept = live.keep[c] != 0u && live.slot[c] < live.capacity;
    const uint64_t slot0 = static_cast<uint64_t>(live.slot[c]) * fm::kChunkSize;
    for (uint64_t i = c * fm::kChunkSize + lane; i < end; i += 32) {
      if (kept && listed_tiles(tiles_touched, chunk_total, slot0 + (i - c * fm::kChunkSize)) > 0) continue;
      float log_scale[3], rotation[4];
      log_scales_of(scene, i, log_scale);
      rotation_of(scene, i, rotation);
      if (fm::unlisted_reaches_image(scene.means + 3 * i, log_scale, rotation, opacity_logit_of(scene, i), cam))
        *outside = 1u;
    }
  }
}

}  // namespace

void check_unlisted(const SceneView& scene, const CameraParams& cam, const CameraParams& key,
                    const uint32_t* tiles_touched, const uint32_t* chunk_total, const LiveChunks& live,
                    unsigned* outside, cudaStream_t stream) {
  if (scene.n == 0) return;
  const uint64_t warps_per_block = tune::kGaussianThreads / 32;
  const uint64_t want = (fm::chunk_count(scene.n) + warps_per_block - 1) / warps_per_block;
  const auto blocks = static_cast<unsigned>(want < 8192 ? want : 8192);
  unlisted_kernel<<<blocks, tune::kGaussianThreads, 0, stream>>>(scene, cam, key, tiles_touched, chunk_total, live,
                                                                 outside);
  CATGS_CUDA_LAUNCHED("unlisted_kernel");
}

std::size_t select_cached_temp_bytes(uint64_t n) {
  std::size_t bytes = 0;
  CATGS_CUDA(cub::DeviceSelect::If(nullptr, bytes, thrust::counting_iterator<uint32_t>(0),
                                   static_cast<uint32_t*>(nullptr), static_cast<unsigned*>(nullptr),
                                   static_cast<int64_t>(n), Listed{nullptr, nullptr}));
  return bytes;
}

void select_cached(const uint32_t* tiles_touched, const uint32_t* chunk_total, uint64_t n, uint32_t* cached,
                   unsigned* count, void* temp, std::size_t temp_bytes, cudaStream_t stream) {
  CATGS_CUDA(cub::DeviceSelect::If(temp, temp_bytes, thrust::counting_iterator<uint32_t>(0), cached, count,
                                   static_cast<int64_t>(n), Listed{tiles_touched, chunk_total}, stream));
}

void update_subframe_features(const SceneView& scene, const CameraParams& cam, const uint32_t* cached, uint32_t count,
                              const uint32_t* live, bool key_colour, const Projected& projected, const Trails& trails,
                              unsigned* outside, cudaStream_t stream) {
  if (count == 0) return;
  const unsigned blocks = (count + tune::kGaussianThreads - 1) / tune::kGaussianThreads;
  subframe_features_kernel<<<blocks, tune::kGaussianThreads, 0, stream>>>(scene, cam, cached, count, live, key_colour,
                                                                          projected, trails, outside);
  CATGS_CUDA_LAUNCHED("subframe_features_kernel");
}

}  // namespace catgs::cuda::stages
