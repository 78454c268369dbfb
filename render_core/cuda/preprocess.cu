// Stage 1: per-Gaussian pre-processing (mirrors cpu/preprocess.cpp line for line, through the
// shared forward_model.h maths). Built with -fmad=false (CMakeLists.txt) so the arithmetic that
// decides culling and tile counts rounds as the CPU reference does, and so the tile test gives the
// same answer here as in key emission.
#include <cub/block/block_reduce.cuh>
#include <cub/device/device_scan.cuh>
#include <stdexcept>

#include "base/cuda_check.h"
#include "splat.cuh"
#include "preprocess.h"
#include "tile_test.cuh"
#include "tunables.h"
#include "warp_reduce.cuh"

namespace catgs::cuda::stages {

namespace {

// Tiles of `rect` (at most 32) the opacity-aware ellipse reaches (exact pipeline), bit b for the
// rectangle's b-th tile in row-major order; their number is count_exact_tiles's on the CPU. With
// an occlusion map, less the entries it hides (fm::entry_hidden, tested only where the ellipse
// reaches the tile, with the ellipse's box worked out once).
__device__ uint32_t exact_tile_mask(const fm::TileRect& rect, glm::vec2 mean, glm::vec3 conic, float q_max, int width,
                                    int height, const fm::OcclusionMap& occlusion, float depth) {
  glm::vec2 half;
  const bool per_entry = occlusion.cells[0] != nullptr && fm::entry_half_widths(conic, q_max, &half);
  uint32_t mask = 0, bit = 1;
  for (int ty = rect.y0; ty < rect.y1; ++ty)
    for (int tx = rect.x0; tx < rect.x1; ++tx, bit <<= 1)
      mask |= fm::ellipse_touches_tile(mean, conic, q_max, tx, ty, width, height) &&
                      !(per_entry && fm::entry_box_hidden(occlusion, mean, half, depth, tx, ty, width, height))
                  ? bit
                  : 0u;
  return mask;
}

// What a warp found over its walk of the chunks, published once at the kernel's end (so the
// walk needs no block barrier): its Gaussians with entries, and its listed depths' range as
// running maxima from zero of the complemented float bits of the nearest (low) and the float bits
// of the farthest (high): positive floats order as their bit patterns.
struct WarpTally {
  unsigned long long visible = 0;
  unsigned low = 0, high = 0;  // this lane's; reduced over the warp in publish
  __device__ void add_depth(bool listed, float depth) {
    const unsigned bits = __float_as_uint(depth);
    low = max(low, listed ? ~bits : 0u);
    high = max(high, listed ? bits : 0u);
  }
  // Into *visible and depth_range[2] (record_big_count's too): one read, and an atomic only where
  // the warp widens the range, so the two shared words see few atomics. Every lane calls it.
  __device__ void publish(unsigned long long* visible_count, unsigned long long* depth_range) const {
    const unsigned warp_low = warp_max(low), warp_high = warp_max(high);
    if ((threadIdx.x & 31u) != 0u) return;
    if (visible > 0) atomicAdd(visible_count, visible);
    const volatile unsigned long long* seen = depth_range;
    if (warp_low > seen[0]) atomicMax(depth_range, static_cast<unsigned long long>(warp_low));
    if (warp_high > seen[1]) atomicMax(depth_range + 1, static_cast<unsigned long long>(warp_high));
  }
};

// Chunk culling, a thread per chunk: exact drops the chunks that cannot reach the image
// (fm::chunk_outside_view; vanilla keeps every chunk, as reference 3DGS culls only per Gaussian)
// and, with occlusion culling, those the last frame's map hides whole (fm::chunk_hidden); every
// pipeline the chunks outside the LOD cut (lod_drawn, cpu/preprocess.cpp's loop).
__global__ void __launch_bounds__(tune::kGaussianThreads)
    cull_chunks_kernel(SceneView scene, uint64_t count, CameraParams cam, bool exact, LiveChunks live,
                       fm::OcclusionMap occlusion) {
  const uint64_t c = static_cast<uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  bool keep = c < count && lod_drawn(scene, c, cam);
  if (keep && exact) {
    const fm::ChunkBounds b = scene.chunks[c];
    keep = !fm::chunk_outside_view(b, cam) && !fm::chunk_hidden(occlusion, b, cam);
  }
  mark_chunk(keep, c, count, live);
}

// order_live_chunks' second launch, a thread per chunk (after slot = the exclusive sum of keep):
// each kept chunk at its slot chunk of index[], and the count from the last chunk.
__global__ void __launch_bounds__(tune::kGaussianThreads) list_live_chunks_kernel(uint64_t count, LiveChunks live) {
  const uint64_t c = static_cast<uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (c >= count) return;
  const uint32_t kept = live.keep[c], at = live.slot[c];
  if (kept) live.index[at] = static_cast<uint32_t>(c);
  if (c + 1 == count) *live.count = at + kept;
}

// Per-entry occlusion culling works from the tile masks of the Gaussians that are not big.
static_assert(fm::kOcclusionEntryTiles == tune::kBigRectTiles, "occlusion.h: the CPU hides the same entries");

// A thread's Gaussian: its mean and opacity, read as the block takes its chunk, and its 3D
// covariance, worked out only where the Gaussian passes the frustum and opacity tests (most are
// culled before).
struct LoadedGaussian {
  glm::vec3 mean;
  float opacity_logit;
  bool have_cov = false;
  fm::Cov3 cov3;
  __device__ LoadedGaussian(const SceneView& scene, uint64_t i)
      : mean(scene.means[3 * i], scene.means[3 * i + 1], scene.means[3 * i + 2]),
        opacity_logit(opacity_logit_of(scene, i)) {}
  __device__ const fm::Cov3& covariance(const SceneView& scene, uint64_t i) {
    if (!have_cov) {
      cov3 = covariance_of(scene, i);
      have_cov = true;
    }
    return cov3;
  }
};

// What one Gaussian gave one view: its tile count (0: not listed), whether it is big or huge
// (counted later by count_big_kernel), and its view depth where listed.
struct GaussianInView {
  uint32_t touched = 0;
  bool is_big = false, is_huge = false;
  float depth = 0.0f;
};

// Gaussian i (loaded as g) in one view: frustum culling, EWA 2D covariance, conic, tile bounds and
// count, SH colour; writes the projected features of a visible one at its slot s and returns its
// counts.
__device__ __forceinline__ GaussianInView preprocess_gaussian(uint64_t i, uint64_t s, LoadedGaussian& g,
                                                              const SceneView& scene, const CameraParams& cam,
                                                              bool exact, const fm::TileRect& region,
                                                              const Projected& out, const fm::OcclusionMap& occlusion) {
  GaussianInView r;
  const glm::vec3 p_cam = cam.R * g.mean + cam.t;
  if (!(p_cam.z > cam.near_plane) || p_cam.z > cam.far_plane) return r;  // frustum (near/far)

  float opacity = fm::sigmoid(g.opacity_logit);
  float q_max = fm::opacity_aware_qmax(opacity);  // vanilla: for the splat's exp cut only
  if (exact && !(q_max > 0.0f)) return r;         // never reaches alpha 1/255 anywhere
  const glm::vec2 mean2d(cam.fx * p_cam.x / p_cam.z + cam.cx - 0.5f, cam.fy * p_cam.y / p_cam.z + cam.cy - 0.5f);
  const glm::vec3 cov2 = fm::covariance_2d(g.covariance(scene, i), cam.R, p_cam, cam.fx, cam.fy, cam.tan_half_fov);
  glm::vec3 conic;
  if (!fm::conic_from_cov2d(cov2, &conic)) return r;
  // A merged Gaussian keeps its coverage under the low-pass (fm::drawn_opacity): a lower peak,
  // and so a tighter q_max (fm::drawn_qmax, a bound of IEEE operations only, so both cores list
  // the same tiles). The culls above read the undrawn opacity's, which is no smaller.
  if (fm::lod_chunk_merged(scene.lod, i / fm::kChunkSize)) {
    const float scale = fm::drawn_scale(cov2, true);
    opacity *= scale;
    q_max = fm::drawn_qmax(q_max, scale);
    if (exact && !(q_max > 0.0f)) return r;
  }
  fm::TileRect rect;
  if (exact) {
    rect = fm::clip_tile_rect(fm::ellipse_tile_rect(mean2d, cov2, q_max, cam.width, cam.height), region);
    const int area = fm::tile_count(rect);
    r.is_big = area > tune::kBigRectTiles;    // counted by count_big_kernel, a warp each
    r.is_huge = area > tune::kHugeRectTiles;  // or a block per part
    const uint32_t mask = area == 0 || r.is_big
                              ? 0u
                              : exact_tile_mask(rect, mean2d, conic, q_max, cam.width, cam.height, occlusion, p_cam.z);
    r.touched = static_cast<uint32_t>(__popc(mask));
    if (r.touched > 0) out.tile_mask[s] = mask;
  } else {
    const float radius = fm::three_sigma_radius(cov2);
    rect = fm::clip_tile_rect(fm::square_tile_rect(mean2d, radius, cam.tiles_x, cam.tiles_y), region);
    r.touched = radius > 0.0f ? static_cast<uint32_t>(fm::tile_count(rect)) : 0u;
    r.is_big = r.touched > static_cast<uint32_t>(tune::kBigRectTiles);  // emitted a warp each
    r.is_huge = r.touched > static_cast<uint32_t>(tune::kHugeRectTiles);
  }
  if (r.touched == 0 && !r.is_big) return r;

  const glm::vec3 dir = glm::normalize(g.mean - cam.position);
  const glm::vec3 col = fm::sh_to_color_from(scene.sh_degree, sh_of(scene, i), dir);
  out.splat[s] = make_splat(mean2d, conic, opacity, q_max);
  out.color[s] = make_float4(col.x, col.y, col.z, 0.0f);
  out.depth[s] = p_cam.z;
  r.depth = p_cam.z;
  out.rect[s] = make_ushort4(static_cast<unsigned short>(rect.x0), static_cast<unsigned short>(rect.y0),
                             static_cast<unsigned short>(rect.x1), static_cast<unsigned short>(rect.y1));
  return r;
}

// One thread per Gaussian of chunk c at slot chunk k (a block's thread x takes Gaussian
// c * kChunkSize + x, slot k * kChunkSize + x), one view: writes the projected features of
// visible Gaussians (preprocess_gaussian) and tiles_touched of every slot (0 past the scene's
// end), adds the warp's entries to the slot chunk's total and its counts to `tally`. Every
// thread of the block calls it.
__device__ __forceinline__ void preprocess_chunk_view(uint64_t c, uint64_t k, LoadedGaussian* g, const SceneView& scene,
                                                      const CameraParams& cam, bool exact, const fm::TileRect& region,
                                                      const Projected& out, WarpTally& tally, const BigList& big,
                                                      const fm::OcclusionMap& occlusion) {
  const uint64_t i = c * fm::kChunkSize + threadIdx.x;
  const uint64_t s = k * fm::kChunkSize + threadIdx.x;
  GaussianInView r;
  if (i < scene.n) r = preprocess_gaussian(i, s, *g, scene, cam, exact, region, out, occlusion);
  out.tiles_touched[s] = r.touched;
  tally.visible += list_big_and_count_warp(r.is_big, r.is_huge, r.touched, s, k, big, out.chunk_total);
  // Big Gaussians' depths count where count_big_kernel finds them entries: the range is over
  // the Gaussians with entries, as the CPU reference's sort works it out from its list.
  tally.add_depth(r.touched > 0, r.depth);
}

// The thread's Gaussian of chunk c (nothing past the scene's end: it is never read).
__device__ __forceinline__ LoadedGaussian load_gaussian(const SceneView& scene, uint64_t c) {
  const uint64_t i = c * fm::kChunkSize + threadIdx.x;
  return LoadedGaussian(scene, i < scene.n ? i : 0);
}

// A block per chunk that cull_chunks_kernel kept (grid-stride over the list: ChunkWalk).
__global__ void __launch_bounds__(tune::kGaussianThreads, tune::kPreprocessMinBlocks)
    preprocess_kernel(SceneView scene, CameraParams cam, bool exact, fm::TileRect region, Projected out, ChunkWalk live,
                      unsigned long long* visible,      // [1] running count of visible Gaussians
                      unsigned long long* depth_range,  // [2] listed depths (WarpTally)
                      BigList big, fm::OcclusionMap occlusion) {
  const uint64_t chunks = live.size();
  WarpTally tally;
  for (uint64_t k = blockIdx.x; k < chunks; k += gridDim.x) {
    const uint64_t c = live.chunk(k);
    LoadedGaussian g = load_gaussian(scene, c);
    preprocess_chunk_view(c, k, &g, scene, cam, exact, region, out, tally, big, occlusion);
  }
  tally.publish(visible, depth_range);
}

// Record of a big Gaussian's count, or of one part's of a huge one (one thread): adds n to its
// tiles_touched (zero from pre-processing) and its chunk's total and, where it has entries and
// depth_range is not null, keeps the depth range as WarpTally does. Returns whether
// this made the Gaussian visible (its first entries), so that each counts once.
__device__ bool record_big_count(uint32_t i, uint32_t n, const float* depth, uint32_t* tiles_touched,
                                 uint32_t* chunk_total, unsigned long long* depth_range) {
  if (n == 0) return false;
  const uint32_t before = atomicAdd(tiles_touched + i, n);
  atomicAdd(chunk_total + i / fm::kChunkSize, n);
  if (depth_range) {
    const unsigned bits = __float_as_uint(depth[i]);
    atomicMax(depth_range, static_cast<unsigned long long>(~bits));
    atomicMax(depth_range + 1, static_cast<unsigned long long>(bits));
  }
  return before == 0;
}

// Big Gaussians, the same tile test as key emission (tile_test.cuh), in two passes of one
// launch: a warp per big Gaussian (32 tiles a round), then a block per part of a huge one
// (kBigThreads tiles a round; huge_parts). Blocks start the second pass as they finish the
// first; the passes share no data. A part's count is kept for key emission (BigList::part_count).
__global__ void __launch_bounds__(tune::kBigThreads) count_big_kernel(BigList big, TileTests tests,
                                                                      const ushort4* rect,                // [N]
                                                                      const float* depth,                 // [N]
                                                                      uint32_t* tiles_touched,            // [N]
                                                                      uint32_t* chunk_total,              // [chunks]
                                                                      unsigned long long* visible,        // [1]
                                                                      unsigned long long* depth_range) {  // [2] or null
  using BlockSum = cub::BlockReduce<uint32_t, tune::kBigThreads>;
  __shared__ typename BlockSum::TempStorage sum_temp;
  const int lane = static_cast<int>(threadIdx.x & 31u);
  const unsigned warps = gridDim.x * (blockDim.x / 32u);
  unsigned long long found = 0;
  for (unsigned w = (blockIdx.x * blockDim.x + threadIdx.x) / 32u; w < big.count[0]; w += warps) {
    const uint32_t i = big.index[w];
    const ushort4 r = rect[i];
    const int rw = r.z - r.x, area = rw * (r.w - r.y);
    const GaussianTileTest hit = load_tile_test(tests, i);
    uint32_t n = 0;
    for (int t = lane; t < area; t += 32) n += hit(r.x + t % rw, r.y + t / rw) ? 1u : 0u;
    n = warp_sum(n);
    if (lane == 0) found += record_big_count(i, n, depth, tiles_touched, chunk_total, depth_range) ? 1u : 0u;
  }
  const uint64_t items = static_cast<uint64_t>(big.count[1]) * tune::kHugeParts;  // (huge one, part)
  for (uint64_t item = blockIdx.x; item < items; item += gridDim.x) {
    const auto h = static_cast<unsigned>(item / tune::kHugeParts);
    const int p = static_cast<int>(item % tune::kHugeParts);
    const uint32_t i = big.huge(h);
    const ushort4 r = rect[i];
    const int rw = r.z - r.x, area = rw * (r.w - r.y);
    const int parts = huge_parts(big, h, area);
    if (p >= parts) continue;  // block-uniform
    const GaussianTileTest hit = load_tile_test(tests, i);
    uint32_t n = 0;
    for (int t = huge_part_first(p, parts, area) + static_cast<int>(threadIdx.x);
         t < huge_part_first(p + 1, parts, area); t += static_cast<int>(blockDim.x))
      n += hit(r.x + t % rw, r.y + t / rw) ? 1u : 0u;
    n = BlockSum(sum_temp).Sum(n);  // valid in thread 0
    if (threadIdx.x == 0) {
      if (parts > 1) big.part_count[static_cast<uint64_t>(h) * tune::kHugeParts + p] = n;
      found += record_big_count(i, n, depth, tiles_touched, chunk_total, depth_range) ? 1u : 0u;
    }
    __syncthreads();  // sum_temp is reused
  }
  if (lane == 0 && found > 0) atomicAdd(visible, found);
}

}  // namespace

std::size_t live_scan_temp_bytes(uint64_t chunks) {
  std::size_t bytes = 0;
  CATGS_CUDA(cub::DeviceScan::ExclusiveSum(nullptr, bytes, static_cast<const uint32_t*>(nullptr),
                                           static_cast<uint32_t*>(nullptr), static_cast<int64_t>(chunks)));
  return bytes;
}

void order_live_chunks(const LiveChunks& live, uint64_t chunks, cudaStream_t stream) {
  if (chunks == 0) return;
  std::size_t temp_bytes = live.scan_temp_bytes;  // CUB takes it by reference
  CATGS_CUDA(cub::DeviceScan::ExclusiveSum(live.scan_temp, temp_bytes, live.keep, live.slot,
                                           static_cast<int64_t>(chunks), stream));
  const auto blocks = static_cast<unsigned>((chunks + tune::kGaussianThreads - 1) / tune::kGaussianThreads);
  list_live_chunks_kernel<<<blocks, tune::kGaussianThreads, 0, stream>>>(chunks, live);
  CATGS_CUDA_LAUNCHED("list_live_chunks_kernel");
}

void clear_chunk_totals(const Projected& out, const LiveChunks& live, cudaStream_t stream) {
  if (live.capacity > 0) CATGS_CUDA(cudaMemsetAsync(out.chunk_total, 0, live.capacity * sizeof(uint32_t), stream));
}

void preprocess(const SceneView& scene, const CameraParams& cam, bool exact, const fm::TileRect& region,
                const Projected& out, const LiveChunks& live, unsigned long long* visible,
                unsigned long long* depth_range, const BigList& big, cudaStream_t stream,
                const fm::OcclusionMap& occlusion) {
  if (scene.n == 0) return;
  const uint64_t chunks = fm::chunk_count(scene.n);
  const uint64_t cull_blocks = (chunks + tune::kGaussianThreads - 1) / tune::kGaussianThreads;
  if (cull_blocks > 0x7fffffffull) throw std::length_error("preprocess: too many Gaussians for one grid");
  clear_chunk_totals(out, live, stream);
  cull_chunks_kernel<<<static_cast<unsigned>(cull_blocks), tune::kGaussianThreads, 0, stream>>>(scene, chunks, cam,
                                                                                                exact, live, occlusion);
  CATGS_CUDA_LAUNCHED("cull_chunks_kernel");
  order_live_chunks(live, chunks, stream);
  const ChunkWalk walk = live.walk();
  preprocess_kernel<<<static_cast<unsigned>(walk.blocks()), tune::kGaussianThreads, 0, stream>>>(
      scene, cam, exact, region, out, walk, visible, depth_range, big, occlusion);
  CATGS_CUDA_LAUNCHED("preprocess_kernel");
  if (!exact) return;
  const TileTests tests{TileTestKind::ellipse, out.splat, {}, cam.width, cam.height};
  count_big_tiles(big, tests, out, visible, depth_range, stream);
}

void count_big_tiles(const BigList& big, const TileTests& tests, const Projected& out, unsigned long long* visible,
                     unsigned long long* depth_range, cudaStream_t stream) {
  count_big_kernel<<<tune::kBigBlocks, tune::kBigThreads, 0, stream>>>(
      big, tests, out.rect, out.depth, out.tiles_touched, out.chunk_total, visible, depth_range);
  CATGS_CUDA_LAUNCHED("count_big_kernel");
}

}  // namespace catgs::cuda::stages
