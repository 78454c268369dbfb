// Stage 5 with task splitting (paper sec. 3.4; mirrors cpu/rasterize_slices.cpp).
//
// Abandoned sub-frames: a sub-frame whose check already found a Gaussian off its trail (the
// `abandon` flag, set by the features and unlisted kernels queued before) is drawn again as a key
// frame, so its slices and merge return at once instead of drawing an image nobody sees.
//
// Tile culling (on by default, CudaOptions::tile_culling): catgs walks a key frame's trail
// list, whose entries reach their tile somewhere along the window but not all at this pose, so
// each round keeps only the entries whose ellipse reaches one of its sub-tiles now
// (blend_range_culled): same image, less blending.
//
// Design. One 256-thread block per slice, thread = pixel, blending the slice's run of the tile's
// list exactly as rasterize.cu blends a whole tile (blend.cuh). Blocks take slices in the order
// the frame's plan computed (task_split.cu: first slices longest first, so the heavy ones start
// early and the short ones fill in behind, then the later slices of split tiles, by their index
// in the tile). A tile that was not split has one slice, which writes C + T * background
// straight into the image: no partials and no merge for the common case. A split tile's slices
// write their partial colour C_k and transmittance T_k to their partial slots (float4 per pixel,
// 4 KiB per slot), and the last of them to finish (a count per tile, slices_done) composes
// C = sum_k C_k prod_{m<k} T_m front to back and adds prod T * background (merge_pixel): no
// merge launch, which cost a block per tile of the image every frame. That block then leaves the
// tile's state (slices_done, saturated_from, slot_finished) as it found it, so the next frame
// over the same plan needs no memsets.
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
// A tile's later slices come after every first slice (task_split.cu), so its first slice usually
// finishes before its later ones start. The image does not depend on timing: where a pixel's composition ends
// is worked out from partials that do not (a slice that did not see an earlier slice finish
// blends the pixel in full, and the merge drops the result), and every slice the merge reads up
// to that end runs in full at that pixel. Without early termination nothing is skipped (that mode
// exists to show split and unsplit agree to float rounding).
#include "blend.cuh"
#include "base/cuda_check.h"
#include "rasterize_slices.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

// A split tile's slice k: stops once an earlier slice of its tile saturated the tile (stop), and
// marks done the pixels whose composition its finished earlier slices already end (refresh, at
// every round of 256 entries): it walks slices 0..k-1 in order while they have finished
// (slot_finished, read before their partials, which are read from L2), with the merge's own rule
// and arithmetic (merge_pixel), so that the two agree exactly. `prefix` is k with early
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

// A split tile's composition at one pixel (its rank, at image index p): C = sum_k C_k
// prod_{m<k} T_m front to back over slices 0..saturated_from, then + prod T * background (paper
// sec. 3.4); with early termination the sum ends after the first slice in which the pixel stopped
// or after which prod T < 1e-4 (as SaturatedSkip::refresh and cpu::rasterize_slices). Partials
// and saturated_from were written by other blocks: read from L2.
// Returns the pixel's opaque point (the occlusion map's P): in the first slice that takes its
// composed T below fm::kOcclusionTransmittance or stops it, the end of the round where its own
// T crossed (`own`: [slots, 256], the slices' PixelState::occluded_from; null: not asked), else
// that slice's end; kNoStop where there is none. The slices the merge reads were never ended for
// this pixel by an earlier one, so `own` is their own walk's, whatever the timing.
__device__ __forceinline__ uint32_t merge_pixel(const SlicePlan& plan, uint32_t tile, uint4 tp, const float4* partials,
                                                const uint32_t* own, bool early_termination, int rank,
                                                float3 background, uint64_t p, float* out_rgb, uint32_t* out_rgba8) {
  float3 C = make_float3(0.0f, 0.0f, 0.0f);
  float T = 1.0f;
  uint32_t ended = kNoStop;
  const uint32_t last = min(tp.y - 1, __ldcg(plan.saturated_from + tile));
  for (uint32_t k = 0; k <= last; ++k) {
    const float4 q = __ldcg(&partials[static_cast<uint64_t>(tp.z + k) * tune::kRasterThreads + rank]);
    C.x += T * q.x;
    C.y += T * q.y;
    C.z += T * q.z;
    T *= fabsf(q.w);
    if (own != nullptr && ended == kNoStop) {
      const uint32_t crossed = __ldcg(&own[static_cast<uint64_t>(tp.z + k) * tune::kRasterThreads + rank]);
      if (crossed != kNoStop)
        ended = crossed;
      else if (q.w < 0.0f || T < fm::kOcclusionTransmittance)
        ended = plan.slice_range[tp.x + k].y;
    }
    if (early_termination && (q.w < 0.0f || T < fm::kMinTransmittance)) break;
  }
  write_pixel(p, C, T, background, out_rgb, out_rgba8);
  return ended;
}

// The per-pixel map (forward_model/occlusion.h): the depth of the entry before the pixel's own
// opaque point `ended`, the largest finite float where it has none.
__device__ __forceinline__ void write_pixel_depth(float* pixel_depth, int px, int py, int width, uint32_t ended,
                                                  const uint32_t* values, const Projected& g) {
  pixel_depth[static_cast<uint64_t>(py) * static_cast<uint64_t>(width) + static_cast<uint64_t>(px)] =
      ended == kNoStop || ended == 0u ? 3.3895314e38f : g.depth[values[ended - 1u]];
}

// kTileCull: blend_range_culled (a trail list) or blend_range (an exact list), as separate
// kernels so that each is built for its own registers (both at 32, with small spills).
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
                            uint32_t* out_rgba8,      // [H, W]
                            OpaquePoints opaque) {    // the occlusion map's P, or none
  __shared__ BlendBatch batch;
  __shared__ uint32_t saturated_at;  // block_max's slot
  if (abandon && *abandon) return;   // written by an earlier kernel: the same for every thread
  const uint32_t s = order ? order[blockIdx.x] : blockIdx.x;
  if (s == kNoSlice) return;  // a block past the slice total (block-uniform)
  const uint2 tile_k = plan.slice_tile[s];
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
      blend_range_culled(range.x, range.y, values, g, at, early_termination, batch, state, skip);
    else
      blend_range(range.x, range.y, values, g, at, early_termination, batch, state, skip);
  };
  if (tp.y == 1) {  // the tile's only slice
    blend(NoSkip{});
    if (opaque.tile != nullptr) {  // block-uniform
      // P: past every pixel's round (a pixel outside the image counts nothing, one that never got
      // there makes it kNoStop).
      const uint32_t P = block_max(inside ? state.occluded_from : 0u, saturated_at);
      if (rank == 0) opaque.tile[tile_k.x] = P == 0u ? kNoStop : P;
    }
    if (!inside) return;
    if (opaque.pixel != nullptr) write_pixel_depth(opaque.pixel, px, py, width, state.occluded_from, values, g);
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
  if (!__syncthreads_or(skip.stop())) {
    const uint64_t slot = static_cast<uint64_t>(tp.z) + tile_k.y;
    blend(skip);
    const bool saturated = state.done || state.T < fm::kMinTransmittance;
    if (early_termination && __syncthreads_and(saturated) && rank == 0 && !skip.stop())
      atomicMin(plan.saturated_from + tile_k.x, tile_k.y);
    // A stopped pixel (done: by early termination here, or ended before this slice, whose
    // partial the merge then never reads) ends its composition: T negated.
    if (inside)
      partials[slot * tune::kRasterThreads + rank] =
          make_float4(state.C.x, state.C.y, state.C.z, state.done ? -state.T : state.T);
    if (inside && opaque.tile != nullptr) opaque.partial[slot * tune::kRasterThreads + rank] = state.occluded_from;
    if (early_termination) {
      __threadfence();  // every thread's partial before the flag (read by later slices of the tile)
      __syncthreads();
      if (rank == 0) atomicExch(plan.slot_finished + slot, 1u);
    }
  }
  // The tile's last slice to finish (skipped ones count) composes the tile and leaves its state
  // as the plan found it, for the next frame over the same plan (a catgs sub-frame).
  __shared__ bool last;
  __threadfence();  // this slice's partials before its count
  __syncthreads();
  if (rank == 0) last = atomicAdd(plan.slices_done + tile_k.x, 1u) == tp.y - 1;
  __syncthreads();
  if (!last) return;
  __threadfence();  // the other slices' partials after their counts
  uint32_t ended = 0u;
  if (inside)
    ended = merge_pixel(plan, tile_k.x, tp, partials, opaque.tile != nullptr ? opaque.partial : nullptr,
                        early_termination, rank, background,
                        static_cast<uint64_t>(py) * static_cast<uint64_t>(width) + static_cast<uint64_t>(px), out_rgb,
                        out_rgba8);
  if (inside && opaque.pixel != nullptr) write_pixel_depth(opaque.pixel, px, py, width, ended, values, g);
  if (opaque.tile != nullptr) {  // block-uniform
    const uint32_t P = block_max(ended, saturated_at);
    if (rank == 0) opaque.tile[tile_k.x] = P == 0u ? kNoStop : P;
  }
  __syncthreads();  // saturated_from read by every pixel's merge
  for (uint32_t k = static_cast<uint32_t>(rank); k < tp.y; k += tune::kRasterThreads) plan.slot_finished[tp.z + k] = 0u;
  if (rank == 0) {
    plan.saturated_from[tile_k.x] = 0xffffffffu;
    plan.slices_done[tile_k.x] = 0u;
  }
}

}  // namespace

void rasterize_slices(const SlicePlan& plan, const uint32_t* order, uint32_t blocks, const uint32_t* sorted_values,
                      const Projected& projected, const CameraParams& cam, bool early_termination, bool tile_culling,
                      float3 background, const unsigned* abandon, float4* partials, float* out_rgb, uint32_t* out_rgba8,
                      cudaStream_t stream, OpaquePoints opaque) {
  if (blocks == 0) return;
  auto* kernel = tile_culling ? rasterize_slices_kernel<true> : rasterize_slices_kernel<false>;
  kernel<<<blocks, tune::kRasterThreads, 0, stream>>>(plan, order, sorted_values, projected, cam.width, cam.height,
                                                      cam.tiles_x, early_termination, background, abandon, partials,
                                                      out_rgb, out_rgba8, opaque);
  CATGS_CUDA_LAUNCHED("rasterize_slices_kernel");
}

}  // namespace catgs::cuda::stages
