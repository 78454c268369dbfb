// Front-to-back blending of a run [begin, end) of the sorted render list over one 16 x 16 tile by
// one 256-thread block (thread = pixel), shared by rasterize.cu (a tile's whole range) and
// rasterize_slices.cu (one slice of it). The design essay is at the top of rasterize.cu: rounds
// of 256 entries fetched into shared memory (bounds-checked), each warp blending only the
// entries that reach its 8 x 4 sub-tile, a block-wide exit once every pixel is done, the
// reference 3DGS blending rule per pixel.
#pragma once

#include "records.h"
#include "tunables.h"
#include "warp_reduce.cuh"

namespace catgs::cuda::stages {

// As catgs::to_unorm8 (renderer.h): clamp to [0, 1], * 255, round half up; NaN to 0.
__device__ __forceinline__ uint32_t unorm8(float v) {
  v = v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f;
  return static_cast<uint32_t>(v * 255.0f + 0.5f);
}

// One staged render-list entry: the 2D mean with the first two terms of the exponent, the third
// with log2(opacity), and the colour (stage_entry), 48 bytes, so that a warp reads an entry with
// two 16-byte loads and a 4-byte one from one address (its offset in the batch, kept in the warp's
// list) instead of working out three.
struct alignas(16) BlendEntry {
  float4 mean_k;       // (x, y, kA, kB)
  float4 kc_log2o_rg;  // (kC, log2(opacity), r, g)
  float b;
};

// One round's entries in shared memory, a null entry after them (alpha 0 everywhere: the walk's
// padding), and the sub-tiles each entry reaches (bit w: warp w's, subtile_mask).
struct BlendBatch {
  BlendEntry entry[tune::kRasterBatch + 1];
  uint32_t subtiles[tune::kRasterBatch];
  // Per warp: byte offsets into `entry` of its entries (blend_batch), read 4 at a time.
  alignas(8) uint16_t warp_list[tune::kRasterThreads / 32][tune::kRasterBatch];
};
inline constexpr uint32_t kNullEntry = tune::kRasterBatch;

// The pixel that thread `rank` of a rasterizer block owns, as an offset from its tile's corner:
// warp w takes the 8 x 4 sub-tile at column w % 2, row w / 2 (tunables.h kSubTileW), lane l the
// pixel (l % 8, l / 8) in it. Every rasterizer kernel and the merge use this one mapping (the
// partial slots of a split tile are indexed by rank).
__device__ __forceinline__ int2 pixel_in_tile(int rank) {
  const int warp = rank >> 5, lane = rank & 31;
  return make_int2((warp & 1) * tune::kSubTileW + (lane & 7), (warp >> 1) * tune::kSubTileH + (lane >> 3));
}

// Where the thread's pixel is: its tile's corner, its rank in the block and its pixel centre.
struct TilePixel {
  int x0, y0;      // the tile's top-left pixel
  int rank;        // thread index in the block
  float fpx, fpy;  // this thread's pixel (x0, y0) + pixel_in_tile(rank)
};

__device__ __forceinline__ TilePixel tile_pixel(int tx, int ty, int rank) {
  const int x0 = tx * tune::kTileSize, y0 = ty * tune::kTileSize;
  const int2 o = pixel_in_tile(rank);
  return {x0, y0, rank, static_cast<float>(x0 + o.x), static_cast<float>(y0 + o.y)};
}

// sqrt(max(x, 0)) through the hardware reciprocal square root (a few ulps off, where the
// callers' margins are 1e-3): 3 instructions instead of sqrtf's IEEE rounding.
__device__ __forceinline__ float rough_sqrt(float x) { return x > 0.0f ? x * rsqrtf(x) : 0.0f; }

// The sub-tiles of the tile at (x0, y0) that a splat's 1/255 ellipse q <= q_max reaches, as a
// bit per warp (bit 2 row + column). A warp skips an entry only where every one of its pixels
// would skip it, so the image is the same bit for bit. Tested against the ellipse itself, not
// its bounding box: a thin Gaussian seen at a slant has a box far wider than itself, and a warp
// walks every entry whose mask holds its bit (docs/history/render_core_rasterizer.md, "Sub-tile
// masks from the ellipse; the mask decides catgs's tile cull").
// For each column of sub-tiles (kSubTileW pixel columns, offsets dx in [a, b] from the mean), the
// ellipse's y-extent over that column: at offset dx the ellipse
// q(dx, dy) = A dx^2 + 2B dx dy + C dy^2 <= Q spans dy = c(dx) +- h(dx), c = -(B / C) dx,
// h = sqrt((Q - D dx^2) / C), D = det / C. Its upper end is concave in dx and peaks at
// dx_t = -B sqrt(Q / (A det)) (where A dx + B dy = 0: the ellipse's point of largest dy),
// its lower end is convex with its trough at -dx_t, so the column's extent is
// [c - h at clamp(-dx_t), c + h at clamp(dx_t)], dx clamped to the column and to the ellipse's
// columns |dx| <= sqrt(Q / D). A sub-tile of the column is reached where that extent meets its
// pixel rows: the ellipse meets the sub-tile's rectangle exactly then. Margins, so that no pixel
// that blend_entry would blend is left out: Q = q_max + 4e-3 + 2e-6 M (blend_entry blends where
// alpha >= 1/255, q <= q_max to within the few ulps of its ex2 and of log2(opacity), under 1e-5
// in q; M bounds the size of the quadratic's terms over the tile, whose few-ulp rounding a thin
// Gaussian's cancelling terms can add to a pixel's q: both err by a few ulps, 6e-8 of M),
// columns widened by 0.02 px, each end by 1e-3 of its terms + 0.02 px, and the ellipse's reach
// by 1e-3 (the hardware divisions and square roots are a few ulps off). Where the ellipse is not
// a finite positive definite one, every sub-tile (blend_entry decides).
__device__ __forceinline__ uint32_t subtile_mask(const Splat& s, int x0, int y0) {
  constexpr uint32_t kAll = (1u << (tune::kSubTilesX * tune::kSubTilesY)) - 1u;
  const float A = s.mean_ab.z, B = s.mean_ab.w, C = s.c_opacity_q_log2.x;
  if (!(s.c_opacity_q_log2.z + 4e-3f > 0.0f)) return 0u;  // culled
  const float lx = s.mean_ab.x - static_cast<float>(x0), ly = s.mean_ab.y - static_cast<float>(y0);
  constexpr float kLast = static_cast<float>(tune::kTileSize - 1);
  const float X = fmaxf(fabsf(lx), fabsf(kLast - lx)), Y = fmaxf(fabsf(ly), fabsf(kLast - ly));
  const float M = fabsf(A) * X * X + 2.0f * fabsf(B) * X * Y + fabsf(C) * Y * Y;
  const float Q = s.c_opacity_q_log2.z + 4e-3f + 2e-6f * M;
  const auto det = static_cast<float>(static_cast<double>(A) * C - static_cast<double>(B) * B);
  const float inv_c = __fdividef(1.0f, C), D = det * inv_c, slope = -B * inv_c;
  const float ex = rough_sqrt(__fdividef(Q, D)) * 1.001f + 0.02f;  // columns reached: |dx| <= ex
  const float dx_t = -B * rough_sqrt(__fdividef(Q, A * det));
  if (!(C > 0.0f && D > 0.0f && ex < INFINITY && fabsf(dx_t) < INFINITY && fabsf(slope) < INFINITY)) return kAll;
  uint32_t mask = 0;
  for (int c = 0; c < tune::kSubTilesX; ++c) {
    const float a = fmaxf(static_cast<float>(c * tune::kSubTileW) - lx - 0.02f, -ex);
    const float b = fminf(static_cast<float>(c * tune::kSubTileW + tune::kSubTileW - 1) - lx + 0.02f, ex);
    if (a > b) continue;
    const float xt = fminf(b, fmaxf(a, dx_t)), xs = fminf(b, fmaxf(a, -dx_t));
    const float ht = rough_sqrt((Q - D * xt * xt) * inv_c), hs = rough_sqrt((Q - D * xs * xs) * inv_c);
    const float ct = slope * xt, cs = slope * xs;
    const float top = ct + ht + 1e-3f * (fabsf(ct) + ht) + 0.02f;
    const float bottom = cs - hs - 1e-3f * (fabsf(cs) + hs) - 0.02f;
    for (int r = 0; r < tune::kSubTilesY; ++r) {
      const float lo = static_cast<float>(r * tune::kSubTileH) - ly;
      const float hi = lo + static_cast<float>(tune::kSubTileH - 1);
      mask |= (bottom <= hi && top >= lo) ? 1u << (tune::kSubTilesX * r + c) : 0u;
    }
  }
  return mask;
}

// log2(e) / 2: the exponent of alpha = opacity exp(-q / 2) in base 2 is
// log2(opacity) - log2(e) q / 2.
constexpr float kHalfLog2e = 0.72134752044448170368f;

// Writes one entry (its splat, colour and sub-tile mask, subtile_mask's for this tile) into
// batch slot `slot`, with the conic pre-scaled so that blend_entry's exponent is in base 2:
// (kA, kB, kC) = -log2(e) (A / 2, B, C / 2).
__device__ __forceinline__ void stage_entry(BlendBatch& batch, uint32_t slot, const Splat& s, float4 color,
                                            uint32_t subtiles) {
  const float4 ab = s.mean_ab, rest = s.c_opacity_q_log2;
  BlendEntry& e = batch.entry[slot];
  e.mean_k = make_float4(ab.x, ab.y, -kHalfLog2e * ab.z, -2.0f * kHalfLog2e * ab.w);
  e.kc_log2o_rg = make_float4(-kHalfLog2e * rest.x, rest.w, color.x, color.y);
  e.b = color.z;
  batch.subtiles[slot] = subtiles;
}

// The walk's padding (blend_batch): a finite entry with log2(opacity) = -inf, which no pixel
// blends. Written by one thread before a run's first barrier.
__device__ __forceinline__ void stage_null_entry(BlendBatch& batch) {
  batch.entry[kNullEntry] = {make_float4(0.0f, 0.0f, 0.0f, 0.0f), make_float4(0.0f, -INFINITY, 0.0f, 0.0f), 0.0f};
}

// log2(alpha) before the clamp, log2(opacity) + log2(e) fm::gaussian_power:
// dx (kA dx + kB dy) + (kC dy^2 + log2(opacity)) with (kA, kB, kC) from stage_entry: 5
// instructions, opacity folded in, written with explicit fmaf so that it rounds alike wherever
// it is inlined. The rasterizers are built with FMA contraction, which the compiler may apply
// differently in different copies, and blend_range and blend_range_culled must agree bit for
// bit (GPU test tilecull).
__device__ __forceinline__ float log2_alpha(float4 m, float kc, float log2o, float dx, float dy) {
  return fmaf(dx, fmaf(m.z, dx, m.w * dy), fmaf(kc * dy, dy, log2o));
}

// 2^x through the hardware's ex2.approx (2 ulps; 0 for x = -inf, subnormal results flushed to 0,
// far below 1/255): one instruction.
__device__ __forceinline__ float fast_exp2(float x) {
  float y;
  asm("ex2.approx.ftz.f32 %0, %1;" : "=f"(y) : "f"(x));
  return y;
}

// Pixel state: colour C and transmittance T (start at 0 and 1); done stops the pixel.
// occluded_from: the end of the round (fm::kOcclusionRound entries from the run's start) in which
// the pixel stopped or its T fell below fm::kOcclusionTransmittance, kNoStop until then
// (blend_range; the occlusion map, forward_model/occlusion.h).
inline constexpr uint32_t kNoStop = 0xffffffffu;
static_assert(tune::kRasterBatch == fm::kOcclusionRound, "the occlusion map's rounds are the rasterizer's");
struct PixelState {
  float3 C;
  float T;
  bool done;
  uint32_t occluded_from = kNoStop;
};

// Blends the batch entry at byte offset `offset` into the pixel at (fpx, fpy) by the reference
// 3DGS rule: skipped where power > 0 or alpha < 1/255; with early termination the pixel stops
// (done) before the entry that would take T below 1e-4, without blending it. A done pixel and the
// null entry blend nothing.
// Without branches: every pixel works out alpha (one ex2, opacity in the exponent) and the rule
// picks what it keeps, so a warp runs one path whatever its pixels decide, and the loads and
// exponentials of the next entries can be issued ahead of this one's transmittance chain
// (blend_batch unrolls). Before, three data-dependent branches a pixel and entry (a power cut
// before the exp, the alpha test, the stop) each cost a compare and a jump and split the warp,
// and the entries ran one after the other. Same rule, rounding apart: the exponent is formed in
// base 2 and T - alpha T with one rounding, so alpha and T differ from the CPU reference's by
// a few ulps (its expf, T (1 - alpha)), as the hardware exp already made them.
__device__ __forceinline__ void blend_entry(const BlendBatch& batch, uint32_t offset, float fpx, float fpy,
                                            bool early_termination, PixelState& px) {
  const BlendEntry& en = *reinterpret_cast<const BlendEntry*>(reinterpret_cast<const char*>(batch.entry) + offset);
  const float4 m = en.mean_k;
  const float4 k = en.kc_log2o_rg;
  const float e = log2_alpha(m, k.x, k.y, m.x - fpx, m.y - fpy);
  const float alpha = fminf(fm::kMaxAlpha, fast_exp2(e));
  // e <= log2(opacity): power <= 0 (the reference skips power > 0).
  const bool keep = !px.done && e <= k.y && alpha >= fm::kMinAlpha;
  const float w = alpha * px.T;
  const float test_T = fmaf(-alpha, px.T, px.T);
  const bool stop = keep && early_termination && test_T < fm::kMinTransmittance;
  const bool blend = keep && !stop;
  px.done = px.done || stop;
  const float wb = blend ? w : 0.0f;
  px.C.x = fmaf(k.z, wb, px.C.x);  // explicit, as log2_alpha
  px.C.y = fmaf(k.w, wb, px.C.y);
  px.C.z = fmaf(en.b, wb, px.C.z);
  px.T = blend ? test_T : px.T;
}

// Blends a round's `count` staged entries, in list order, into the pixel at (fpx, fpy) of warp
// `warp`. The warp first lists the entries whose sub-tile mask holds its bit (a ballot over 32
// masks at a time, each hit's slot from the popcount of the hits before it), then walks that list,
// so an entry that misses the sub-tile costs its warp nothing, and a hit costs a one-byte load
// and a counter instead of the find-first-set, clear and test of walking each ballot's set bits
// (rasterization 1-7% faster, images the same: docs/history/render_core_rasterizer.md, "Warps
// walk lists of their entries"). A warp whose
// pixels are all done leaves (checked every 32 hits). Skipped entries are ones every pixel of the
// sub-tile would skip (subtile_mask), so the pixel blends what a walk of every entry blends.
__device__ __forceinline__ void blend_batch(BlendBatch& batch, uint32_t count, const TilePixel& at,
                                            bool early_termination, PixelState& px) {
  constexpr unsigned kAll = 0xffffffffu;
  const uint32_t bit = 1u << (at.rank >> 5);
  const auto lane = static_cast<uint32_t>(at.rank & 31);
  uint16_t* list = batch.warp_list[at.rank >> 5];
  uint32_t hits = 0;
  for (uint32_t base = 0; base < count; base += 32) {
    const uint32_t j = base + lane;
    const bool hit = j < count && (batch.subtiles[j] & bit) != 0u;
    const uint32_t ballot = __ballot_sync(kAll, hit);
    if (hit)
      list[hits + static_cast<uint32_t>(__popc(ballot & ((1u << lane) - 1u)))] =
          static_cast<uint16_t>(j * sizeof(BlendEntry));
    hits += static_cast<uint32_t>(__popc(ballot));
  }
  // The walk reads four offsets a load: the list is padded to a multiple of 4 with the null
  // entry, which blends nothing (stage_null_entry).
  if (lane < 3 && hits + lane < static_cast<uint32_t>(tune::kRasterBatch))
    list[hits + lane] = static_cast<uint16_t>(kNullEntry * sizeof(BlendEntry));
  __syncwarp();  // the list before its reads
  for (uint32_t k0 = 0; k0 < hits; k0 += 32) {
    if (__all_sync(kAll, px.done)) break;
    const uint32_t end = min(hits, k0 + 32u);
    for (uint32_t k = k0; k < end; k += 4) {
      const uint2 four = *reinterpret_cast<const uint2*>(list + k);
      blend_entry(batch, four.x & 0xffffu, at.fpx, at.fpy, early_termination, px);
      blend_entry(batch, four.x >> 16, at.fpx, at.fpy, early_termination, px);
      blend_entry(batch, four.y & 0xffffu, at.fpx, at.fpy, early_termination, px);
      blend_entry(batch, four.y >> 16, at.fpx, at.fpy, early_termination, px);
    }
  }
  __syncwarp();  // every read of the list before the next round writes it
}

// Blends entries [begin, end) into `px` (the pixel of thread at.rank). With
// early_termination a pixel stops before the Gaussian that would take T below 1e-4 (as the
// reference 3DGS); without it, blends to the end. `skip.stop()` (block-uniform) ends the run
// early, and `skip.refresh(px)` (per thread, before each round) may mark the pixel done
// (rasterize_slices.cu: pixels an earlier slice already ended); every thread of
// the block must call this (barriers inside).
template <typename Skip>
__device__ __forceinline__ void blend_range(uint32_t begin, uint32_t end,
                                            const uint32_t* values,  // [L]
                                            const Projected& g, const TilePixel& at, bool early_termination,
                                            BlendBatch& batch, PixelState& px, Skip skip) {
  if (at.rank == 0) stage_null_entry(batch);  // before the first barrier below
  for (uint32_t base = begin; base < end; base += tune::kRasterBatch) {
    skip.refresh(px);
    if (__syncthreads_count(px.done || skip.stop()) == tune::kRasterThreads) break;
    const uint32_t fetch = base + static_cast<uint32_t>(at.rank);
    if (fetch < end) {  // bounds-checked prefetch
      const uint32_t gi = values[fetch];
      const Splat sp = g.splat[gi];
      stage_entry(batch, static_cast<uint32_t>(at.rank), sp, g.color[gi], subtile_mask(sp, at.x0, at.y0));
    }
    __syncthreads();
    blend_batch(batch, min(static_cast<uint32_t>(tune::kRasterBatch), end - base), at, early_termination, px);
    if (px.occluded_from == kNoStop && (px.done || px.T < fm::kOcclusionTransmittance))
      px.occluded_from = min(end, base + static_cast<uint32_t>(tune::kRasterBatch));
    __syncthreads();  // shared memory is refilled next round
  }
}

// The largest `v` over the block (every thread of the block must call it; a barrier inside).
__device__ __forceinline__ uint32_t block_max(uint32_t v, uint32_t& shared_slot) {
  if (threadIdx.x == 0) shared_slot = 0u;
  __syncthreads();
  v = warp_max(v);
  if ((threadIdx.x & 31u) == 0u) atomicMax(&shared_slot, v);
  __syncthreads();
  return shared_slot;
}

// As blend_range, for a list whose entries need not reach this tile at this pose (catgs: a key
// frame's trail list, walked at the key pose or at a sub-frame's pose). Each round, the thread
// that fetches an entry works out its sub-tile mask (subtile_mask: the sub-tiles its ellipse
// q <= q_max reaches at this frame's features, with margins for rounding), and only the entries
// that reach a sub-tile are compacted into shared memory, in list (depth) order. A dropped entry
// would have been skipped by every pixel of the tile (alpha < 1/255 there), so the image is the
// same bit for bit; what is saved is the blending of every entry that does not reach the tile
// now (a trail list holds several times the exact list on the city's real paths:
// tests/gpu/RESULTS.md, "Where the tuned defaults come from"). Culled sub-frame Gaussians
// (q_max -inf) reach none.
// - The test reads only the entry's splat (one random 32-byte sector, stages.h Splat); the
//   colour, a second sector, is gathered for the kept entries only. The mask serves both the cull
//   and the warps' walk: one ellipse test per fetched entry
//   (docs/history/render_core_rasterizer.md, "Sub-tile masks from the ellipse; the mask decides
//   catgs's tile cull": before, an exact tile test decided the cull and the mask was worked out
//   after it).
// Every thread of the block must call this (barriers inside); `skip.stop()` (block-uniform) ends
// the run early.
template <typename Skip>
__device__ __forceinline__ void blend_range_culled(uint32_t begin, uint32_t end,
                                                   const uint32_t* values,  // [L]
                                                   const Projected& g, const TilePixel& at, bool early_termination,
                                                   BlendBatch& batch, PixelState& px, Skip skip) {
  constexpr int kWarps = tune::kRasterThreads / 32;
  __shared__ uint32_t warp_kept[kWarps];
  const int lane = at.rank & 31, warp = at.rank >> 5;
  if (at.rank == 0) stage_null_entry(batch);  // before the first barrier below
  for (uint32_t base = begin; base < end; base += tune::kRasterBatch) {
    skip.refresh(px);
    if (__syncthreads_count(px.done || skip.stop()) == tune::kRasterThreads) break;
    const uint32_t fetch = base + static_cast<uint32_t>(at.rank);
    uint32_t gi = 0, subtiles = 0;
    Splat sp{};
    if (fetch < end) {  // bounds-checked prefetch
      gi = values[fetch];
      sp = g.splat[gi];
      subtiles = subtile_mask(sp, at.x0, at.y0);
    }
    const bool keep = subtiles != 0u;
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
      stage_entry(batch, slot, sp, g.color[gi], subtiles);
    }
    __syncthreads();
    blend_batch(batch, count, at, early_termination, px);
    __syncthreads();  // shared memory (batch and warp_kept) is refilled next round
  }
}

// A whole tile's range: nothing ends it early but its own pixels.
struct NoSkip {
  __device__ __forceinline__ void refresh(PixelState&) const {}
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
