// Front-to-back blending of a run [begin, end) of the sorted render list over one 16 x 16 tile by
// one 256-thread block (thread = pixel), shared by rasterize.cu (a tile's whole range) and
// rasterize_slices.cu (one slice of it). The design essay is at the top of rasterize.cu: rounds
// of 256 entries fetched into shared memory (bounds-checked), a block-wide exit once every pixel
// is done, the reference 3DGS blending rule per pixel.
#pragma once

#include "stages.h"
#include "tunables.h"

namespace catgs::cuda::stages {

// As catgs::to_unorm8 (renderer.h): clamp to [0, 1], * 255, round half up.
__device__ __forceinline__ uint32_t unorm8(float v) {
  v = v < 0.0f ? 0.0f : (v > 1.0f ? 1.0f : v);
  return static_cast<uint32_t>(v * 255.0f + 0.5f);
}

// One round's entries in shared memory.
struct BlendBatch {
  float2 mean[tune::kRasterBatch];
  float4 conic_opacity[tune::kRasterBatch];
  float4 color[tune::kRasterBatch];
};

// Pixel state: colour C and transmittance T (start at 0 and 1); done stops the pixel.
struct PixelState {
  float3 C;
  float T;
  bool done;
};

// Blends batch entry j into the pixel at (fpx, fpy) by the reference 3DGS rule: skipped where
// power > 0 or alpha < 1/255; with early termination the pixel stops (done) before the entry that
// would take T below 1e-4, without blending it.
__device__ __forceinline__ void blend_entry(const BlendBatch& batch, uint32_t j, float fpx, float fpy,
                                            bool early_termination, PixelState& px) {
  const float2 m = batch.mean[j];
  const float4 co = batch.conic_opacity[j];
  const float power = fm::gaussian_power(glm::vec3(co.x, co.y, co.z), m.x - fpx, m.y - fpy);
  if (power > 0.0f) return;
  const float alpha = fminf(fm::kMaxAlpha, co.w * expf(power));
  if (alpha < fm::kMinAlpha) return;
  const float test_T = px.T * (1.0f - alpha);
  if (early_termination && test_T < fm::kMinTransmittance) {
    px.done = true;
    return;
  }
  const float4 c = batch.color[j];
  const float w = alpha * px.T;
  px.C.x += c.x * w;
  px.C.y += c.y * w;
  px.C.z += c.z * w;
  px.T = test_T;
}

// Blends entries [begin, end) into `px` (the pixel at (fpx, fpy) of thread `rank`). With
// early_termination a pixel stops before the Gaussian that would take T below 1e-4 (as the
// reference 3DGS); without it, blends to the end. `skip(j)` (warp-uniform) lets a caller drop
// batch entry j for its warp, and `skip.stop()` (block-uniform) ends the run early; every thread
// of the block must call this (barriers inside).
template <typename Skip>
__device__ __forceinline__ void blend_range(uint32_t begin, uint32_t end,
                                            const uint32_t* values,         // [L]
                                            const Projected& g, int rank, float fpx, float fpy,
                                            bool early_termination, BlendBatch& batch, PixelState& px,
                                            Skip skip) {
  for (uint32_t base = begin; base < end; base += tune::kRasterBatch) {
    if (__syncthreads_count(px.done || skip.stop()) == tune::kRasterThreads) break;
    const uint32_t fetch = base + static_cast<uint32_t>(rank);
    if (fetch < end) {  // bounds-checked prefetch
      const uint32_t gi = values[fetch];
      batch.mean[rank] = g.mean2d[gi];
      batch.conic_opacity[rank] = g.conic_opacity[gi];
      batch.color[rank] = g.color[gi];
      skip.fetch(rank, gi, batch);
    }
    __syncthreads();
    const uint32_t count = min(static_cast<uint32_t>(tune::kRasterBatch), end - base);
    for (uint32_t j = 0; j < count && !px.done; ++j) {
      if (skip(j)) continue;
      blend_entry(batch, j, fpx, fpy, early_termination, px);
    }
    __syncthreads();  // shared memory is refilled next round
  }
}

// As blend_range, for a list whose entries need not reach this tile at this pose (catgs: a key
// frame's trail list, walked at the key pose or at a sub-frame's pose). Each round, the thread
// that fetches an entry also asks the exact pipeline's own list test, fm::ellipse_touches_tile
// (opacity-aware ellipse q <= q_max at this frame's features, widened by kExactQMargin), whether
// it reaches tile (tx, ty), and only the entries that do are compacted into shared memory, in
// list (depth) order. A dropped entry would have been skipped by every pixel of the tile (alpha <
// 1/255 there), so the image is the same bit for bit; what is saved is 256 pixels' worth of
// blending per dropped entry (a trail list holds 1.4-2.3x the exact list on real paths,
// RESULTS.md). Culled sub-frame Gaussians (opacity 0) are dropped too. Every thread of the block
// must call this (barriers inside); `skip.stop()` (block-uniform) ends the run early.
template <typename Skip>
__device__ __forceinline__ void blend_range_culled(uint32_t begin, uint32_t end,
                                                   const uint32_t* values,  // [L]
                                                   const Projected& g, int rank, int tx, int ty, int width,
                                                   int height, float fpx, float fpy, bool early_termination,
                                                   BlendBatch& batch, PixelState& px, Skip skip) {
  constexpr int kWarps = tune::kRasterThreads / 32;
  __shared__ uint32_t warp_kept[kWarps];
  const int lane = rank & 31, warp = rank >> 5;
  for (uint32_t base = begin; base < end; base += tune::kRasterBatch) {
    if (__syncthreads_count(px.done || skip.stop()) == tune::kRasterThreads) break;
    const uint32_t fetch = base + static_cast<uint32_t>(rank);
    bool keep = false;
    uint32_t gi = 0;
    float2 m{};
    float4 co{};
    if (fetch < end) {  // bounds-checked prefetch
      gi = values[fetch];
      m = g.mean2d[gi];
      co = g.conic_opacity[gi];
      keep = co.w > 0.0f && fm::ellipse_touches_tile(glm::vec2(m.x, m.y), glm::vec3(co.x, co.y, co.z),
                                                     g.q_max[gi], tx, ty, width, height);
    }
    const uint32_t ballot = __ballot_sync(0xffffffffu, keep);
    if (lane == 0) warp_kept[warp] = static_cast<uint32_t>(__popc(ballot));
    __syncthreads();
    uint32_t slot = 0, count = 0;
    for (int w = 0; w < kWarps; ++w) {
      const uint32_t c = warp_kept[w];
      slot += w < warp ? c : 0u;
      count += c;
    }
    if (keep) {
      slot += static_cast<uint32_t>(__popc(ballot & ((1u << lane) - 1u)));
      batch.mean[slot] = m;
      batch.conic_opacity[slot] = co;
      batch.color[slot] = g.color[gi];
    }
    __syncthreads();
    for (uint32_t j = 0; j < count && !px.done; ++j) {
      blend_entry(batch, j, fpx, fpy, early_termination, px);
    }
    __syncthreads();  // shared memory (batch and warp_kept) is refilled next round
  }
}

// No per-warp skipping.
struct NoSkip {
  __device__ __forceinline__ void fetch(int, uint32_t, const BlendBatch&) const {}
  __device__ __forceinline__ bool operator()(uint32_t) const { return false; }
  __device__ __forceinline__ bool stop() const { return false; }
};

// Writes C + T * background as float RGB and packed RGBA8 at pixel p.
__device__ __forceinline__ void write_pixel(uint64_t p, float3 C, float T, float3 background, float* out_rgb,
                                            uint32_t* out_rgba8) {
  C.x += T * background.x;
  C.y += T * background.y;
  C.z += T * background.z;
  out_rgb[3 * p] = C.x;
  out_rgb[3 * p + 1] = C.y;
  out_rgb[3 * p + 2] = C.z;
  out_rgba8[p] = unorm8(C.x) | (unorm8(C.y) << 8) | (unorm8(C.z) << 16) | (255u << 24);
}

}  // namespace catgs::cuda::stages
