// catgs key frame, stage 1: pre-processing over the speculation window (paper sec. 3.1; mirrors
// cpu/speculative_preprocess.cpp line for line through forward_model.h), and the planner's M.
// Built with FMA contraction, unlike the other stages that decide tile membership
// (CMakeLists.txt): emission never asks this kernel's tile test again (small trails hand it
// their answers as bit masks, big ones are counted and emitted by key_emission.cu from the
// stored trail), so counting and emission agree; what contraction changes is the last bits of a
// trail against the CPU reference's, which only widens or narrows a trail by float rounding.
#include "forward_model/chunk_bounds.h"
#include "forward_model/trail.h"
#include "base/cuda_check.h"
#include "splat.cuh"
#include "preprocess.h"  // count_big_tiles
#include "speculative_preprocess.h"
#include "tile_test.cuh"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

// One thread per Gaussian: project at every camera of the path, build the trail (fm::build_trail),
// count the tiles it touches (big trails are left to count_big_tiles, a warp each). Local arrays
// hold the path's samples: 33 x 20 bytes per thread, in L1-cached local memory. Held to 64
// registers (4 blocks of 256 per SM, 20 bytes of spill): the kernel is compute-bound, and at 72
// registers (3 blocks) it was slower (tunables.h kPathKernelMinBlocks).
// A block per chunk of the walk (thread x takes Gaussian chunk * kChunkSize + x, and slot
// k * kChunkSize + x of the outputs); every thread calls it.
__device__ __forceinline__ void speculative_preprocess_chunk(uint64_t chunk, uint64_t k, const SceneView& scene,
                                                             const PathParams& path, const TrailWidening& widening,
                                                             const Projected& out, const Trails& trails,
                                                             unsigned long long* visible, const BigList& big) {
  const uint64_t i = chunk * fm::kChunkSize + threadIdx.x;
  const uint64_t s = k * fm::kChunkSize + threadIdx.x;
  uint32_t touched = 0;
  bool is_big = false, is_huge = false;
  if (i < scene.n) {
    do {
      const float opacity = fm::sigmoid(opacity_logit_of(scene, i));
      const float q_max = fm::opacity_aware_qmax(opacity);
      if (!(q_max > 0.0f)) break;
      const glm::vec3 mean(scene.means[3 * i], scene.means[3 * i + 1], scene.means[3 * i + 2]);
      // The cheap cull before any 2D covariance (forward_model.h, shared with the CPU core).
      float log_scale[3];
      log_scales_of(scene, i, log_scale);
      if (fm::path_misses_image(
              mean, log_scale, q_max, path.count, [&](int k) -> const fm::View& { return path.cam[k]; }, widening.slack,
              widening.margin_px, widening.motion_margin))
        break;
      float rotation[4];
      rotation_of(scene, i, rotation);
      const fm::Cov3 cov3 = fm::covariance_3d({log_scale[0], log_scale[1], log_scale[2]},
                                              {rotation[0], rotation[1], rotation[2], rotation[3]});
      glm::vec2 means[kMaxPathCameras];
      glm::vec3 covs[kMaxPathCameras];
      int seen = 0;
      float key_depth = 0.0f;
      for (int k = 0; k < path.count; ++k) {
        const CameraParams& c = path.cam[k];
        const glm::vec3 p = c.R * mean + c.t;
        if (!(p.z > c.near_plane) || p.z > c.far_plane) {
          if (k == 0) break;  // the key camera must see it (the key depth orders the list)
          continue;
        }
        const glm::vec3 cov2 = fm::covariance_2d(cov3, c.R, p, c.fx, c.fy, c.tan_half_fov);
        if (cov2.x * cov2.z - cov2.y * cov2.y <= 0.0f) {
          if (k == 0) break;
          continue;
        }
        means[seen] = glm::vec2(c.fx * p.x / p.z + c.cx - 0.5f, c.fy * p.y / p.z + c.cy - 0.5f);
        covs[seen] = cov2;
        if (k == 0) key_depth = p.z;
        ++seen;
      }
      if (seen == 0) break;  // not visible at the key camera
      const fm::Trail trail =
          fm::build_trail(means, covs, seen, q_max, widening.slack, widening.margin_px, widening.motion_margin);
      glm::vec3 conic, trail_conic;
      if (!fm::conic_from_cov2d(covs[0], &conic) || !fm::conic_from_cov2d(trail.cov, &trail_conic)) break;
      const CameraParams& key = path.cam[0];
      const fm::TileRect rect =
          fm::trail_tile_rect(trail.mean0, trail.motion, trail.cov, trail.q_trail, key.width, key.height);
      const int area = fm::tile_count(rect);
      is_big = area > tune::kBigRectTiles;    // counted by count_big_tiles, a warp each
      is_huge = area > tune::kHugeRectTiles;  // or a block per part
      uint32_t mask = 0;                      // row-major bit per tile of the rectangle
      if (area > 0 && !is_big) {
        const fm::TrailTileTest test = fm::make_trail_tile_test(trail.mean0, trail.motion, trail_conic, trail.q_trail);
        for (int ty = rect.y0, bit = 0; ty < rect.y1; ++ty)
          for (int tx = rect.x0; tx < rect.x1; ++tx, ++bit)
            if (fm::trail_touches_tile(test, tx, ty, key.width, key.height)) mask |= 1u << bit;
      }
      touched = static_cast<uint32_t>(__popc(mask));
      if (touched == 0 && !is_big) break;

      const glm::vec3 c = fm::sh_to_color_from(scene.sh_degree, sh_of(scene, i), glm::normalize(mean - key.position));
      // Drawn at the key view (fm::drawn_opacity); q_max stays the undrawn opacity's, no smaller,
      // so the trail's tiles still hold every pixel the sub-frames blend.
      const float drawn = fm::drawn_opacity(opacity, covs[0], fm::lod_chunk_merged(scene.lod, i / fm::kChunkSize));
      out.splat[s] = make_splat(means[0], conic, drawn, q_max);
      out.color[s] = make_float4(c.x, c.y, c.z, 0.0f);
      out.depth[s] = key_depth;
      out.rect[s] = make_ushort4(static_cast<unsigned short>(rect.x0), static_cast<unsigned short>(rect.y0),
                                 static_cast<unsigned short>(rect.x1), static_cast<unsigned short>(rect.y1));
      trails.mean0_motion[s] = make_float4(trail.mean0.x, trail.mean0.y, trail.motion.x, trail.motion.y);
      trails.conic_q[s] = make_float4(trail_conic.x, trail_conic.y, trail_conic.z, trail.q_trail);
      trails.cov[s] = make_float4(trail.cov.x, trail.cov.y, trail.cov.z, trail.q_trail);
      trails.tile_mask[s] = mask;
    } while (false);
  }
  out.tiles_touched[s] = touched;  // 0 past the scene's end
  list_big_and_count_visible(is_big, is_huge, touched, s, k, big, visible, out.chunk_total);
}

__global__ void __launch_bounds__(tune::kGaussianThreads, tune::kPathKernelMinBlocks)
    speculative_preprocess_kernel(SceneView scene, PathParams path, TrailWidening widening, Projected out,
                                  Trails trails, ChunkWalk live,
                                  unsigned long long* visible,  // [1]
                                  BigList big) {
  const uint64_t chunks = live.size();
  for (uint64_t k = blockIdx.x; k < chunks; k += gridDim.x) {
    speculative_preprocess_chunk(live.chunk(k), k, scene, path, widening, out, trails, visible, big);
    __syncthreads();  // the block reduction's shared words are rewritten next round
  }
}

// Chunk culling over the path, a thread per chunk (fm::chunk_misses_path: a chunk none of whose
// Gaussians the per-Gaussian cull above would keep), and the chunks outside the LOD cut at the
// key view (lod_drawn at path.cam[0]: the whole window draws the key frame's cut).
__global__ void __launch_bounds__(tune::kGaussianThreads)
    cull_path_chunks_kernel(SceneView scene, uint64_t count, PathParams path, TrailWidening widening, LiveChunks live) {
  const uint64_t c = static_cast<uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  const auto view_at = [&](int k) -> const fm::View& { return path.cam[k]; };
  mark_chunk(c < count && lod_drawn(scene, c, path.cam[0]) &&
                 !fm::chunk_misses_path(scene.chunks[c], path.count, view_at, 1.0f + widening.slack, widening.margin_px,
                                        widening.motion_margin),
             c, count, live);
}

// M: a warp per chunk (grid-stride over the scene's chunks), the chunk skipped whole when none
// of its means can count (fm::chunk_means_off_image: on a scene of many copies most chunks lie
// off the key image, and M read every mean at every key frame that wanted a window), else its
// 32 lanes read its means (coalesced); a warp reduction, one atomicMax per warp. Chunks outside
// the LOD cut at `a` (the key view) do not count.
__global__ void __launch_bounds__(tune::kGaussianThreads)
    max_screen_motion_kernel(SceneView scene, CameraParams a, CameraParams b, float min_depth,
                             unsigned* max_bits) {  // [1]
  const float* means = scene.means;                 // [N, 3]
  const uint64_t n = scene.n;
  float m = 0.0f;
  const uint64_t chunk_count = fm::chunk_count(n);
  const uint64_t warps = static_cast<uint64_t>(gridDim.x) * blockDim.x / 32u;
  const auto lane = static_cast<unsigned>(threadIdx.x & 31u);
  for (uint64_t c = (static_cast<uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x) / 32u; c < chunk_count; c += warps) {
    if (!lod_drawn(scene, c, a) || fm::chunk_means_off_image(scene.chunks[c], a, min_depth)) continue;  // warp-uniform
    const uint64_t end = min(n, (c + 1) * fm::kChunkSize);
    for (uint64_t i = c * fm::kChunkSize + lane; i < end; i += 32u) {
      const glm::vec3 x(means[3 * i], means[3 * i + 1], means[3 * i + 2]);
      const glm::vec3 pa = a.R * x + a.t, pb = b.R * x + b.t;
      if (!(pa.z > min_depth) || !(pb.z > a.near_plane)) continue;
      const glm::vec2 ua(a.fx * pa.x / pa.z + a.cx, a.fy * pa.y / pa.z + a.cy);
      if (ua.x < 0 || ua.y < 0 || ua.x > static_cast<float>(a.width) || ua.y > static_cast<float>(a.height)) continue;
      const glm::vec2 ub(b.fx * pb.x / pb.z + b.cx, b.fy * pb.y / pb.z + b.cy);
      m = fmaxf(m, glm::length(ub - ua));
    }
  }
  for (int off = 16; off > 0; off >>= 1) m = fmaxf(m, __shfl_xor_sync(0xffffffffu, m, off));
  if (lane == 0 && m > 0.0f) atomicMax(max_bits, __float_as_uint(m));
}

}  // namespace

void speculative_preprocess(const SceneView& scene, const PathParams& path, const TrailWidening& widening,
                            const Projected& out, const Trails& trails, const LiveChunks& live,
                            unsigned long long* visible, const BigList& big, cudaStream_t stream) {
  if (path.count < 1 || path.count > kMaxPathCameras)
    throw std::invalid_argument("speculation path must hold 1.." + std::to_string(kMaxPathCameras) + " cameras");
  if (scene.n == 0) return;
  const uint64_t chunks = fm::chunk_count(scene.n);
  const uint64_t cull_blocks = (chunks + tune::kGaussianThreads - 1) / tune::kGaussianThreads;
  if (cull_blocks > 0x7fffffffull) throw std::length_error("speculative_preprocess: too many Gaussians for one grid");
  clear_chunk_totals(out, live, stream);
  cull_path_chunks_kernel<<<static_cast<unsigned>(cull_blocks), tune::kGaussianThreads, 0, stream>>>(
      scene, chunks, path, widening, live);
  CATGS_CUDA_LAUNCHED("cull_path_chunks_kernel");
  order_live_chunks(live, chunks, stream);
  const ChunkWalk walk = live.walk();
  speculative_preprocess_kernel<<<static_cast<unsigned>(walk.blocks()), tune::kGaussianThreads, 0, stream>>>(
      scene, path, widening, out, trails, walk, visible, big);
  CATGS_CUDA_LAUNCHED("speculative_preprocess_kernel");
  const TileTests tests{TileTestKind::trail, nullptr, trails, path.cam[0].width, path.cam[0].height};
  count_big_tiles(big, tests, out, visible, nullptr, stream);
}

void max_screen_motion(const SceneView& scene, const CameraParams& a, const CameraParams& b, float min_depth,
                       unsigned* max_bits, cudaStream_t stream) {
  if (scene.n == 0) return;
  const uint64_t warps_per_block = tune::kGaussianThreads / 32;
  const uint64_t want = (fm::chunk_count(scene.n) + warps_per_block - 1) / warps_per_block;
  const auto blocks = static_cast<unsigned>(want < 4096 ? want : 4096);
  max_screen_motion_kernel<<<blocks, tune::kGaussianThreads, 0, stream>>>(scene, a, b, min_depth, max_bits);
  CATGS_CUDA_LAUNCHED("max_screen_motion_kernel");
}

}  // namespace catgs::cuda::stages
