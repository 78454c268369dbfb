// Stage 5: tile rasterization, front-to-back alpha blending (mirrors cpu/rasterize.cpp).
//
// Design.
// - One 256-thread block per 16 x 16 tile, blocks taking the tiles heaviest first (tile_order); thread (x, y) of the block owns pixel
//   (16 tx + x, 16 ty + y) and keeps its colour C and transmittance T in registers. Threads whose
//   pixel lies outside the image (right and bottom border tiles) start "done" but stay in the
//   block: they still fetch Gaussians for the others and take part in every barrier.
// - The tile's range [start, end) of the sorted render list is walked in rounds of 256 entries.
//   In a round each thread fetches one entry (Gaussian index, 2D mean, conic + opacity, colour)
//   into shared memory: one coalesced read of the value array and 256 independent gathers in
//   flight, instead of 256 threads each re-reading the same Gaussian from global memory. Every
//   fetch is bounds-checked against `end` (a tile holding fewer entries than a round, one or two
//   say, fetches only those: DESIGN.md's FlashGS lesson). Each gather reads the entry's 32-byte
//   splat and its 16-byte colour: two sectors (stages.h Splat).
// - After the barrier every thread blends the round's Gaussians in depth order, skipping those
//   with power > 0 or alpha < 1/255, and stops before the Gaussian that would take T below 1e-4
//   (the reference 3DGS rule, as on the CPU). A pixel whose power lies below the entry's
//   power_cut (splat.cuh: ln(1 / (255 opacity)), less a margin) skips before the exp: most pixels
//   of a tile lie outside most of its Gaussians' 1/255 ellipses, and the answer is the same. A
//   second barrier protects shared memory before the next fetch.
// - Early termination: __syncthreads_count(done) at the top of each round ends the whole block
//   once all its pixels are saturated, so opaque tiles never walk the rest of their list.
// - One pixel per thread on purpose: blocks of 16 x 8 threads owning two pixels each, reading
//   each shared-memory entry once for both, drew the same image but rasterized 1.2-1.7x slower
//   (H100, city exact bicycle 0.89 -> 1.46 ms; tests/gpu/RESULTS.md, 2026-11-22), likely because
//   the blend loop is bound by latency and half the warps per SM were left to hide it.
// - Shared memory: 256 x (16 + 16 + 16) bytes = 12 KiB per block, so occupancy is set by
//   registers, not shared memory. Colour is stored as float4 so each fetch is one 16-byte load.
// - Optional, exact pipeline only (CudaRenderer::set_warp_culling, off by default): when a thread
//   fetches an entry it also works out which of the block's 8 warps (each owns 16 x 2 pixels) lie
//   within the vertical extent of the Gaussian's opacity-aware ellipse, and stores an 8-bit mask.
//   A warp skips an entry whose bit is clear: each of its pixels would have found alpha < 1/255
//   and skipped it anyway, so the image is bit-identical. Measured on H100 (catgs-bench variant
//   exact-warp): a full per-strip ellipse test cost more than it saved, so it stays off.
// - Output: float RGB (C + T * background) and packed 8-bit RGBA, both in device memory, so a
//   later encoder can read the frame without a host copy.
#include "blend.cuh"
#include "cuda_check.h"
#include "stages.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

constexpr int kWarps = tune::kRasterThreads / 32;
constexpr int kRowsPerWarp = 32 / tune::kTileSize;
static_assert(kWarps <= 8, "warp masks are 8 bits");
static_assert(32 % tune::kTileSize == 0, "a warp covers whole pixel rows of its tile");

// Bit w set: warp w's rows of the tile whose first pixel row is y0 meet the vertical extent of
// the ellipse q <= q_max, |dy| <= sqrt(q_max * cov_yy) with cov_yy = A / (A C - B^2) from the
// conic. Widened by a relative 1e-3 (and the tile test's q margin) so float rounding of the
// inverse can only keep an entry, never drop one a pixel would have blended. Cheap on purpose
// (one sqrt, one division): it runs once per fetched entry, ahead of the block's barrier.
__device__ __forceinline__ uint32_t warp_mask(const Splat& s, float y0) {
  const float A = s.mean_ab.z, B = s.mean_ab.w, C = s.c_opacity_q_cut.x, q_max = s.c_opacity_q_cut.z;
  const float det = A * C - B * B;
  const float cov_yy = A / det;
  const float hy = sqrtf(fmaxf(0.0f, (q_max + fm::kExactQMargin) * cov_yy)) * 1.001f + 1e-3f;
  const float lo = ceilf(s.mean_ab.y - hy - y0), hi = floorf(s.mean_ab.y + hy - y0);
  if (!(lo <= hi) || hi < 0.0f || lo > static_cast<float>(tune::kTileSize - 1)) return 0u;
  const int r0 = static_cast<int>(fmaxf(lo, 0.0f)) / kRowsPerWarp;
  const int r1 = static_cast<int>(fminf(hi, static_cast<float>(tune::kTileSize - 1))) / kRowsPerWarp;
  return ((2u << r1) - 1u) & ~((1u << r0) - 1u);
}

// The optional per-warp skip (exact pipeline): fetch stores the warp mask of each entry, and a warp
// skips the entries whose bit is clear.
struct WarpSkip {
  uint8_t* mask;       // [kRasterBatch] shared
  float y0;
  int warp;
  __device__ __forceinline__ void refresh(PixelState&) const {}
  __device__ __forceinline__ void fetch(int rank, const Splat& s) const {
    mask[rank] = static_cast<uint8_t>(warp_mask(s, y0));
  }
  __device__ __forceinline__ bool operator()(uint32_t j) const { return !((mask[j] >> warp) & 1u); }
  __device__ __forceinline__ bool stop() const { return false; }
};

template <bool kWarpCull>
__global__ void __launch_bounds__(tune::kRasterThreads)
rasterize_kernel(const uint2* ranges,          // [tiles] [start, end) into the sorted list
                 const uint32_t* tile_order,   // [tiles] or null
                 const uint32_t* values,       // [L] sorted Gaussian indices
                 Projected g,                  // [N] features
                 int width, int height, int tiles_x, float3 background,
                 float* out_rgb,               // [H, W, 3]
                 uint32_t* out_rgba8) {        // [H, W]
  __shared__ BlendBatch batch;
  __shared__ uint8_t s_mask[kWarpCull ? tune::kRasterBatch : 1];

  const uint32_t tile = tile_order ? tile_order[blockIdx.x] : blockIdx.x;
  const int tx = static_cast<int>(tile % static_cast<uint32_t>(tiles_x));
  const int ty = static_cast<int>(tile / static_cast<uint32_t>(tiles_x));
  const int rank = threadIdx.y * tune::kTileSize + threadIdx.x;
  const int px = tx * tune::kTileSize + threadIdx.x, py = ty * tune::kTileSize + threadIdx.y;
  const bool inside = px < width && py < height;

  const uint2 range = ranges[tile];
  PixelState state{make_float3(0.0f, 0.0f, 0.0f), 1.0f, !inside};
  if constexpr (kWarpCull) {
    const WarpSkip skip{s_mask, static_cast<float>(ty * tune::kTileSize), rank / 32};
    blend_range(range.x, range.y, values, g, rank, static_cast<float>(px), static_cast<float>(py), true, batch,
                state, skip);
  } else {
    blend_range(range.x, range.y, values, g, rank, static_cast<float>(px), static_cast<float>(py), true, batch,
                state, NoSkip{});
  }
  if (!inside) return;
  write_pixel(static_cast<uint64_t>(py) * static_cast<uint64_t>(width) + static_cast<uint64_t>(px), state.C,
              state.T, background, out_rgb, out_rgba8);
}

}  // namespace

void rasterize(const uint2* ranges, const uint32_t* tile_order, const uint32_t* sorted_values,
               const Projected& projected, const CameraParams& cam, bool warp_cull, float3 background, float* out_rgb,
               uint32_t* out_rgba8, cudaStream_t stream) {
  const auto tiles = static_cast<unsigned>(cam.tiles_x * cam.tiles_y);
  const dim3 block(tune::kTileSize, tune::kTileSize);
  auto kernel = warp_cull ? rasterize_kernel<true> : rasterize_kernel<false>;
  kernel<<<tiles, block, 0, stream>>>(ranges, tile_order, sorted_values, projected, cam.width, cam.height,
                                      cam.tiles_x, background, out_rgb, out_rgba8);
  CATGS_CUDA_LAUNCHED("rasterize_kernel");
}

}  // namespace catgs::cuda::stages
