// Stage 5 with task splitting (paper sec. 3.4; mirrors cpu/rasterize_slices.cpp).
//
// Abandoned sub-frames: a sub-frame whose check already found a Gaussian off its trail (the
// `abandon` flag, set by the features and unlisted kernels queued before) is drawn again as a key
// frame, so its slices and merge return at once instead of drawing an image nobody sees.
//
// Tile culling (on by default, CudaRenderer::set_tile_culling): catgs walks a key frame's trail
// list, whose entries reach their tile somewhere along the window but not all at this pose, so
// each round keeps only the entries whose ellipse reaches the tile now (blend_range_culled): same
// image, less blending.
//
// Design. One 256-thread block per slice, thread = pixel, blending the slice's run of the tile's
// list exactly as rasterize.cu blends a whole tile (blend.cuh). Blocks take slices in the order
// the key frame computed (longest first, so the heavy slices start early and the short ones fill
// in behind). A tile that was not split has one slice, which writes C + T * background straight
// into the image: no partials and no merge for the common case. A split tile's slices write
// their partial colour C_k and transmittance T_k to their partial slots (float4 per pixel,
// 4 KiB per slot), and merge_kernel, a block per split tile, composes
// C = sum_k C_k prod_{m<k} T_m front to back and adds prod T * background.
//
// Saturated pixels and tiles. Without splitting, a pixel that saturates stops walking its tile's
// list; split, its later slices would start afresh with T = 1 and blend Gaussians that are hidden
// there. So with early termination a pixel's composition ends at the first slice in which it
// stops (its partial T is stored negated) or after which prod T < 1e-4; the merge drops its later
// slices, each weighted by prod T < 1e-4, under a third of an 8-bit level: the "higher
// early-termination threshold for later slices" the paper allows.
// - Per pixel: a slice, before it blends, reads the partials of its tile's earlier slices that
//   have finished (slot_finished, set after a slice's partials are written and fenced) and
//   marks done the pixels whose composition they already end. Those pixels blend nothing here.
// - Per tile: a slice k that saturates every pixel of its tile (stopped, T < 1e-4, or ended
//   before it) records k in saturated_from[tile] (atomicMin); slices behind it skip their work,
//   at the start and at every round of 256 entries, and the merge composes slices
//   0..saturated_from only.
// Slices are ordered k first (task_split.cu), so a tile's first slice usually finishes before
// its later ones start. The image does not depend on timing: where a pixel's composition ends
// is worked out from partials that do not (a slice that did not see an earlier slice finish
// blends the pixel in full, and the merge drops the result), and every slice the merge reads up
// to that end runs in full at that pixel. Without early termination nothing is skipped (that mode
// exists to show split and unsplit agree to float rounding).
#include "blend.cuh"
#include "cuda_check.h"
#include "rasterize_slices.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

// A split tile's slice k: stops once an earlier slice of its tile saturated the tile (stop), and
// marks done the pixels whose composition its finished earlier slices already end (refresh, at
// every round of 256 entries): it walks slices 0..k-1 in order while they have finished
// (slot_finished, read before their partials, which are read from L2), with the merge's own rule
// and arithmetic (merge_kernel), so that the two agree exactly. `prefix` is k with early
// termination and 0 without (no pixel ends early then).
struct SaturatedSkip {
  const volatile unsigned* saturated_from;  // this tile's entry
  unsigned k;
  const unsigned* slot_finished;  // [k] this tile's slots
  const float4* partials;         // [k, 256] this tile's, at this thread's pixel
  unsigned prefix;
  unsigned known = 0;  // earlier slices walked
  float T = 1.0f;      // prod of their T at this pixel
  __device__ __forceinline__ bool stop() const { return *saturated_from < k; }
  __device__ __forceinline__ void refresh(PixelState& px) {
    while (!px.done && known < prefix) {
      if (*static_cast<const volatile unsigned*>(slot_finished + known) == 0u) return;  // not yet known
      __threadfence();  // the flag before the partial it guards
      const float w = __ldcg(&partials[static_cast<uint64_t>(known) * tune::kRasterThreads].w);
      T *= fabsf(w);
      ++known;
      if (w < 0.0f || T < fm::kMinTransmittance) px.done = true;
    }
  }
};

// kTileCull: blend_range_culled (a trail list) or blend_range (an exact list), as separate
// kernels so that each is built for its own registers: the unculled one fits 32 without spilling.
// Together they took 48, which capped the culled kernel at 5 blocks per SM (ncu, city bicycle
// sub-frames: 54% achieved occupancy, 36% of cycles with no eligible warp, against exact's 32
// registers and 91%).
template <bool kTileCull>
__global__ void __launch_bounds__(tune::kRasterThreads, tune::kRasterMinBlocks)
    rasterize_slices_kernel(SlicePlan plan,
                            const uint32_t* order,   // [blocks] or null
                            const uint32_t* values,  // [L] sorted Gaussian indices
                            Projected g, int width, int height, int tiles_x, bool early_termination, float3 background,
                            const unsigned* abandon,  // [1] or null: non-zero, draw nothing
                            float4* partials,         // [slots, 256] (C.rgb, T)
                            float* out_rgb,           // [H, W, 3]
                            uint32_t* out_rgba8) {    // [H, W]
  __shared__ BlendBatch batch;
  if (abandon && *abandon) return;  // written by an earlier kernel: the same for every thread
  const uint32_t s = order ? order[blockIdx.x] : blockIdx.x;
  const uint2 tile_k = plan.slice_tile[s];
  if (tile_k.x == 0xffffffffu) return;  // a slot past the slice total (block-uniform)
  const uint2 range = plan.slice_range[s];
  const uint4 tp = plan.tile_plan[tile_k.x];
  const int tx = static_cast<int>(tile_k.x % static_cast<uint32_t>(tiles_x));
  const int ty = static_cast<int>(tile_k.x / static_cast<uint32_t>(tiles_x));
  const TilePixel at = tile_pixel(tx, ty, static_cast<int>(threadIdx.x));
  const int rank = at.rank;
  const int px = static_cast<int>(at.fpx), py = static_cast<int>(at.fpy);
  const bool inside = px < width && py < height;

  PixelState state{make_float3(0.0f, 0.0f, 0.0f), 1.0f, !inside};
  // Blends this slice's run, with or without the per-round tile cull (blend.cuh).
  auto blend = [&](auto skip) {
    if constexpr (kTileCull)
      blend_range_culled(range.x, range.y, values, g, tx, ty, width, height, at, early_termination, batch, state, skip);
    else
      blend_range(range.x, range.y, values, g, at, early_termination, batch, state, skip);
  };
  if (tp.y == 1) {  // the tile's only slice
    blend(NoSkip{});
    if (!inside) return;
    write_pixel(static_cast<uint64_t>(py) * static_cast<uint64_t>(width) + static_cast<uint64_t>(px), state.C, state.T,
                background, out_rgb, out_rgba8);
    return;
  }
  const SaturatedSkip skip{plan.saturated_from + tile_k.x, tile_k.y, plan.slot_finished + tp.z,
                           partials + static_cast<uint64_t>(tp.z) * tune::kRasterThreads + rank,
                           early_termination && inside ? tile_k.y : 0u};
  // Another block may saturate the tile while this one reads the flag, so threads can disagree:
  // decide together (a thread leaving alone would break the barriers and the warp ballots of
  // blend_range_culled, which faulted with an illegal instruction on the H100).
  if (__syncthreads_or(skip.stop())) return;
  const uint64_t slot = static_cast<uint64_t>(tp.z) + tile_k.y;
  blend(skip);
  const bool saturated = state.done || state.T < fm::kMinTransmittance;
  if (early_termination && __syncthreads_and(saturated) && rank == 0 && !skip.stop())
    atomicMin(plan.saturated_from + tile_k.x, tile_k.y);
  // A stopped pixel (done: by early termination here, or ended before this slice, whose partial
  // the merge then never reads) ends its composition: T negated.
  if (inside)
    partials[slot * tune::kRasterThreads + rank] =
        make_float4(state.C.x, state.C.y, state.C.z, state.done ? -state.T : state.T);
  if (!early_termination) return;
  __threadfence();  // every thread's partial before the flag (read by later slices of the tile)
  __syncthreads();
  if (rank == 0) atomicExch(plan.slot_finished + slot, 1u);
}

__global__ void __launch_bounds__(tune::kRasterThreads)
    merge_kernel(SlicePlan plan,
                 const float4* __restrict__ partials,  // [slots, 256]
                 int width, int height, int tiles_x, bool early_termination, float3 background,
                 const unsigned* abandon,             // [1] or null
                 float* __restrict__ out_rgb,         // [H, W, 3]
                 uint32_t* __restrict__ out_rgba8) {  // [H, W]
  if (abandon && *abandon) return;
  const uint4 tp = plan.tile_plan[blockIdx.x];
  if (tp.y <= 1) return;  // written by its only slice
  const int tx = static_cast<int>(blockIdx.x % static_cast<uint32_t>(tiles_x));
  const int ty = static_cast<int>(blockIdx.x / static_cast<uint32_t>(tiles_x));
  const int rank = static_cast<int>(threadIdx.x);
  const int2 o = pixel_in_tile(rank);  // the slices' pixel for this rank
  const int px = tx * tune::kTileSize + o.x, py = ty * tune::kTileSize + o.y;
  if (px >= width || py >= height) return;
  float3 C = make_float3(0.0f, 0.0f, 0.0f);
  float T = 1.0f;
  const uint32_t last = min(tp.y - 1, plan.saturated_from[blockIdx.x]);
  for (uint32_t k = 0; k <= last; ++k) {
    const float4 p = partials[static_cast<uint64_t>(tp.z + k) * tune::kRasterThreads + rank];
    C.x += T * p.x;
    C.y += T * p.y;
    C.z += T * p.z;
    T *= fabsf(p.w);
    // The pixel stopped in slice k, or the slices behind weigh under 1e-4 (as SaturatedSkip::refresh).
    if (early_termination && (p.w < 0.0f || T < fm::kMinTransmittance)) break;
  }
  write_pixel(static_cast<uint64_t>(py) * static_cast<uint64_t>(width) + static_cast<uint64_t>(px), C, T, background,
              out_rgb, out_rgba8);
}

}  // namespace

void rasterize_slices(const SlicePlan& plan, const uint32_t* order, uint32_t blocks, const uint32_t* sorted_values,
                      const Projected& projected, const CameraParams& cam, bool early_termination, bool tile_culling,
                      float3 background, const unsigned* abandon, float4* partials, float* out_rgb, uint32_t* out_rgba8,
                      cudaStream_t stream) {
  CATGS_CUDA(cudaMemsetAsync(plan.saturated_from, 0xff,
                             sizeof(unsigned) * static_cast<std::size_t>(cam.tiles_x * cam.tiles_y), stream));
  CATGS_CUDA(cudaMemsetAsync(plan.slot_finished, 0, sizeof(unsigned) * plan.slot_count, stream));
  if (blocks == 0) return;
  auto* kernel = tile_culling ? rasterize_slices_kernel<true> : rasterize_slices_kernel<false>;
  kernel<<<blocks, tune::kRasterThreads, 0, stream>>>(plan, order, sorted_values, projected, cam.width, cam.height,
                                                      cam.tiles_x, early_termination, background, abandon, partials,
                                                      out_rgb, out_rgba8);
  CATGS_CUDA_LAUNCHED("rasterize_slices_kernel");
}

void merge_slices(const SlicePlan& plan, const float4* partials, const CameraParams& cam, bool early_termination,
                  float3 background, const unsigned* abandon, float* out_rgb, uint32_t* out_rgba8,
                  cudaStream_t stream) {
  const auto tiles = static_cast<unsigned>(cam.tiles_x * cam.tiles_y);
  merge_kernel<<<tiles, tune::kRasterThreads, 0, stream>>>(plan, partials, cam.width, cam.height, cam.tiles_x,
                                                           early_termination, background, abandon, out_rgb, out_rgba8);
  CATGS_CUDA_LAUNCHED("merge_kernel");
}

}  // namespace catgs::cuda::stages
