// Device helpers shared by the pre-processing and key-emission kernels.
//
// The tile-membership test of stage 2, loaded once per Gaussian into registers and then asked
// per tile: square (vanilla: every tile of the rectangle), ellipse (exact: fm::ellipse_touches_tile)
// or trail (catgs key frames: fm::trail_touches_tile, its constants made once per Gaussian by
// fm::make_trail_tile_test). The same test counts tiles in stage 1 and emits keys in stage 2, so
// both agree (both files are built with -fmad=false); a small trail's emission skips the test and
// reads the answers stage 1 kept (Trails::tile_mask).
#pragma once

#include "forward_model/forward_model.h"
#include "forward_model/trail.h"
#include "records.h"
#include "warp_reduce.cuh"

namespace catgs::cuda::stages {

struct GaussianTileTest {
  TileTestKind kind;
  glm::vec2 mean;           // ellipse: 2D mean
  glm::vec3 conic;          // ellipse conic
  float q;                  // q_max
  fm::TrailTileTest trail;  // trail: its constants, worked out once per Gaussian
  int width, height;

  __device__ __forceinline__ bool operator()(int tx, int ty) const {
    switch (kind) {
      case TileTestKind::ellipse:
        return fm::ellipse_touches_tile(mean, conic, q, tx, ty, width, height);
      case TileTestKind::trail:
        return fm::trail_touches_tile(trail, tx, ty, width, height);
      default:
        return true;
    }
  }
};

__device__ __forceinline__ GaussianTileTest load_tile_test(const TileTests& t, uint64_t i) {
  GaussianTileTest g{t.kind, {}, {}, 0.0f, {}, t.width, t.height};
  if (t.kind == TileTestKind::ellipse) {
    const Splat s = t.splat[i];
    g.mean = glm::vec2(s.mean_ab.x, s.mean_ab.y);
    g.conic = glm::vec3(s.mean_ab.z, s.mean_ab.w, s.c_opacity_q_log2.x);
    g.q = s.c_opacity_q_log2.z;
  } else if (t.kind == TileTestKind::trail) {
    const float4 mm = t.trails.mean0_motion[i];
    const float4 cq = t.trails.conic_q[i];
    g.trail = fm::make_trail_tile_test(glm::vec2(mm.x, mm.y), glm::vec2(mm.z, mm.w), glm::vec3(cq.x, cq.y, cq.z), cq.w);
  }
  return g;
}

// Big Gaussians join the big list, huge ones (is_huge implies is_big) its huge end: one atomic
// per warp holding any (they are few). Called by every lane of the warp.
__device__ __forceinline__ void list_big(bool is_big, bool is_huge, uint64_t i, const BigList& big) {
  const int lane = static_cast<int>(threadIdx.x & 31u);
  for (int list = 0; list < 2; ++list) {  // 0: big (not huge), 1: huge
    const bool mine = list == 0 ? is_big && !is_huge : is_huge;
    const unsigned lanes = __ballot_sync(0xffffffffu, mine);
    if (lanes == 0u) continue;  // warp-uniform
    const int leader = __ffs(lanes) - 1;
    unsigned base = 0;
    if (lane == leader) base = atomicAdd(big.count + list, static_cast<unsigned>(__popc(lanes)));
    base = __shfl_sync(0xffffffffu, base, leader);
    const uint64_t at = base + static_cast<unsigned>(__popc(lanes & ((1u << lane) - 1u)));
    if (mine) big.index[list == 0 ? at : big.capacity - 1 - at] = static_cast<uint32_t>(i);
  }
}

// The warp's share of its chunk, without a block barrier (exact pre-processing: its warps then
// never wait for the block's slowest, which tests occlusion and colours the most Gaussians):
// list_big, and the warp's tiles_touched added to chunk `chunk`'s Projected::chunk_total (one
// atomic per warp with entries, onto the zeros of clear_chunk_totals). Returns the warp's
// Gaussians with entries (every lane), which the caller adds up over its walk and publishes once.
// Called by every lane of the warp.
__device__ __forceinline__ uint32_t list_big_and_count_warp(bool is_big, bool is_huge, uint32_t touched, uint64_t i,
                                                            uint64_t chunk, const BigList& big, uint32_t* chunk_total) {
  list_big(is_big, is_huge, i, big);
  const uint32_t total = warp_sum(touched);
  if ((threadIdx.x & 31u) == 0u && total > 0u) atomicAdd(chunk_total + chunk, total);
  return static_cast<uint32_t>(__popc(__ballot_sync(0xffffffffu, touched > 0)));
}

// The end of the speculative pre-processing kernel, called by every thread of the block: list_big,
// and the visible count takes one atomic per block, not per Gaussian (docs/DESIGN.md "Lessons
// kept from the founding design": no contended atomics); the block's chunk `chunk` gets the sum of
// its tiles_touched (Projected::chunk_total). Big Gaussians are counted visible, and added to their
// chunk's total, by count_big_tiles once their tiles are known.
__device__ __forceinline__ void list_big_and_count_visible(bool is_big, bool is_huge, uint32_t touched, uint64_t i,
                                                           uint64_t chunk, const BigList& big,
                                                           unsigned long long* visible, uint32_t* chunk_total) {
  __shared__ uint32_t warp_total[tune::kGaussianThreads / 32];
  const int lane = static_cast<int>(threadIdx.x & 31u);
  list_big(is_big, is_huge, i, big);
  const uint32_t total = warp_sum(touched);
  if (lane == 0) warp_total[threadIdx.x / 32u] = total;
  const int block_visible = __syncthreads_count(touched > 0);
  if (threadIdx.x == 0) {  // no return: a kernel may walk several chunks (records.h ChunkWalk)
    uint32_t block_total = 0;
    for (unsigned w = 0; w < blockDim.x / 32u; ++w) block_total += warp_total[w];
    chunk_total[chunk] = block_total;
    if (block_visible > 0) atomicAdd(visible, static_cast<unsigned long long>(block_visible));
  }
}

// Chunk culling's answer for chunk c < count (a thread per chunk): order_live_chunks lists the
// kept ones in index order.
__device__ __forceinline__ void mark_chunk(bool keep, uint64_t c, uint64_t count, const LiveChunks& live) {
  if (c < count) live.keep[c] = keep ? 1u : 0u;
}

// The parts a huge Gaussian (the h-th of the huge list, `area` rectangle tiles) is cut into
// (tunables.h kHugeParts): a block each in count_big_tiles and key emission, which must agree.
// Part p holds the rectangle's tiles [huge_part_first(p), huge_part_first(p + 1)) in row-major
// order.
__device__ __forceinline__ int huge_parts(const BigList& big, unsigned h, int area) {
  if (h >= static_cast<unsigned>(tune::kHugeListed)) return 1;
  return min(tune::kHugeParts, (area + tune::kHugePartTiles - 1) / tune::kHugePartTiles);
}
__device__ __forceinline__ int huge_part_first(int p, int parts, int area) { return p * area / parts; }

}  // namespace catgs::cuda::stages
