// Stage 5: tile rasterization, front-to-back alpha blending (mirrors cpu/rasterize.cpp).
//
// Design.
// - One 256-thread block per 16 x 16 tile, blocks taking the tiles heaviest first (tile_order,
//   stage 4b); each warp owns an 8 x 4 sub-tile (blend.cuh pixel_in_tile), each thread one pixel
//   of it, and keeps its colour C and transmittance T in registers. Threads whose
//   pixel lies outside the image (right and bottom border tiles) start "done" but stay in the
//   block: they still fetch Gaussians for the others and take part in every barrier.
// - The tile's range [start, end) of the sorted render list is walked in rounds of 256 entries.
//   In a round each thread fetches one entry (Gaussian index, 2D mean, conic + opacity, colour)
//   into shared memory: one coalesced read of the value array and 256 independent gathers in
//   flight, instead of 256 threads each re-reading the same Gaussian from global memory. Every
//   fetch is bounds-checked against `end` (a tile holding fewer entries than a round, one or two
//   say, fetches only those: the FlashGS lesson of docs/DESIGN.md "Lessons kept from the
//   founding design"). Each gather reads the entry's 32-byte splat and its 16-byte colour: two
//   sectors (stages.h Splat).
// - When it stages an entry, the fetching thread also works out which sub-tiles the entry's
//   ellipse can reach (the ellipse over each column of sub-tiles: blend.cuh subtile_mask), and
//   each warp then walks only the round's entries that reach its sub-tile (it lists them first,
//   a ballot over 32 masks at a time, then walks its list: blend.cuh blend_batch).
//   Small Gaussians reach a few of a tile's 8 sub-tiles, so most warps skip most entries at no
//   cost, where before every pixel evaluated every entry (docs/history/render_core_rasterizer.md,
//   "Sub-tile rasterization").
// - After the barrier every thread blends the round's Gaussians in depth order, skipping those
//   with power > 0 or alpha < 1/255, and stops before the Gaussian that would take T below 1e-4
//   (the reference 3DGS rule, as on the CPU), without branches: alpha = 2^(log2(opacity) +
//   log2(e) power) for every entry a warp walks, and the rule selects what the pixel keeps
//   (blend.cuh blend_entry; 4 entries a step, so the next entries' loads and exponentials issue
//   ahead of this one's transmittance). A second barrier protects shared memory before the next
//   fetch.
// - Early termination: __syncthreads_count(done) at the top of each round ends the whole block
//   once all its pixels are saturated, so opaque tiles never walk the rest of their list.
// - One pixel per thread on purpose: blocks of 16 x 8 threads owning two pixels each, reading
//   each shared-memory entry once for both, drew the same image but rasterized slower, likely
//   because the blend loop is bound by latency and half the warps per SM were left to hide it
//   (docs/history/render_core_rasterizer.md, "Two pixels per thread (tried)").
// - Shared memory: 257 x 48 bytes of entries (the last a null entry that pads the warps' walks),
//   256 x 4 bytes of sub-tile masks and 8 x 256 x 2 bytes of warp lists = 17 KiB per block, so
//   occupancy is set by registers, not shared memory.
// - Output: float RGB (C + T * background) and packed 8-bit RGBA, both in device memory, so a
//   later encoder can read the frame without a host copy.
#include "blend.cuh"
#include "base/cuda_check.h"
#include "rasterize.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

__global__ void __launch_bounds__(tune::kRasterThreads, tune::kRasterMinBlocks)
    rasterize_kernel(const uint2* __restrict__ ranges,         // [tiles] [start, end) into the sorted list
                     const uint32_t* __restrict__ tile_order,  // [blocks], from first_tile
                     uint32_t first_tile,
                     const uint32_t* __restrict__ values,  // [L] sorted Gaussian indices
                     Projected g,                          // [N] features
                     int width, int height, int tiles_x, float3 background,
                     float* __restrict__ out_rgb,         // [H, W, 3]
                     uint32_t* __restrict__ out_rgba8) {  // [H, W]
  __shared__ BlendBatch batch;

  const uint32_t tile = first_tile + tile_order[blockIdx.x];
  const int tx = static_cast<int>(tile % static_cast<uint32_t>(tiles_x));
  const int ty = static_cast<int>(tile / static_cast<uint32_t>(tiles_x));
  const TilePixel at = tile_pixel(tx, ty, static_cast<int>(threadIdx.x));
  const int px = static_cast<int>(at.fpx), py = static_cast<int>(at.fpy);
  const bool inside = px < width && py < height;

  const uint2 range = ranges[tile];
  PixelState state{make_float3(0.0f, 0.0f, 0.0f), 1.0f, !inside};
  blend_range(range.x, range.y, values, g, at, true, batch, state, NoSkip{});
  if (!inside) return;
  write_pixel(static_cast<uint64_t>(py) * static_cast<uint64_t>(width) + static_cast<uint64_t>(px), state.C, state.T,
              background, out_rgb, out_rgba8);
}

}  // namespace

void rasterize(const uint2* ranges, const uint32_t* tile_order, uint32_t first_tile, uint32_t tile_count,
               const uint32_t* sorted_values, const Projected& projected, const CameraParams& cam, float3 background,
               float* out_rgb, uint32_t* out_rgba8, cudaStream_t stream) {
  if (tile_count == 0) return;
  rasterize_kernel<<<tile_count, tune::kRasterThreads, 0, stream>>>(ranges, tile_order, first_tile, sorted_values,
                                                                    projected, cam.width, cam.height, cam.tiles_x,
                                                                    background, out_rgb, out_rgba8);
  CATGS_CUDA_LAUNCHED("rasterize_kernel");
}

}  // namespace catgs::cuda::stages
