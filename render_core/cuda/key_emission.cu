// Stage 2: render-list key emission (mirrors cpu/key_emission.cpp). Offsets come from a device
// scan of the chunks' entry counts and a block scan within each chunk, so no Gaussian ever
// touches a shared counter (docs/DESIGN.md "Lessons kept from the founding design":
// FlashGS's contended global atomicAdd per Gaussian is what slows it on the city). Built with
// -fmad=false, like pre-processing, so the exact tile test here answers exactly as it did when
// the tiles were counted.
#include <algorithm>

#include <cub/block/block_reduce.cuh>
#include <cub/block/block_scan.cuh>
#include <cub/device/device_scan.cuh>
#include <thrust/iterator/transform_iterator.h>

#include "base/cuda_check.h"
#include "key_emission.h"
#include "tile_test.cuh"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

struct WidenToU64 {
  __host__ __device__ uint64_t operator()(uint32_t v) const { return v; }
};

using WideCounts = thrust::transform_iterator<WidenToU64, const uint32_t*, uint64_t>;

static_assert(tune::kGaussianThreads == fm::kChunkSize, "a block of the per-Gaussian kernels is a chunk");
static_assert(static_cast<uint64_t>(fm::kChunkSize) * tune::kMaxTilesPerSide * tune::kMaxTilesPerSide < (1ull << 32),
              "a chunk's entry count (each Gaussian lists at most every tile once) fits Projected::chunk_total");

// Where a key goes (forward_model/key_packing.h): the 64-bit key into `wide`, or the 32-bit one
// into `narrow` when that is not null (the single sort's [tile | quantised depth], or the tile id
// alone for the depth-first sort's second pass). The choice is uniform over a launch.
struct KeyOut {
  uint64_t* wide;    // [L]
  uint32_t* narrow;  // [L] or null
  DepthKeyPacking packing;
  // Tile-only keys (the depth-first sort's) read no depth.
  __device__ bool needs_depth() const { return packing.bits > 0; }
  __device__ void put(uint64_t at, uint32_t tile, uint32_t depth_bits) const {
    if (narrow)
      narrow[at] = packing.key32(tile, depth_bits);
    else
      wide[at] = packing.key64(tile, depth_bits);
  }
};

// counts[0] += the chunks' entries (this block's share of a grid-stride sum: a block reduction,
// then one atomic), counts[1] = visible Gaussians (block 0).
constexpr int kCountThreads = 1024;
__global__ void __launch_bounds__(kCountThreads)
    count_list_kernel(const uint32_t* __restrict__ chunk_total,  // [chunks]
                      uint64_t chunks,
                      const unsigned long long* __restrict__ visible,  // [1]
                      unsigned long long* counts) {                    // [2], counts[0] zeroed
  using Reduce = cub::BlockReduce<unsigned long long, kCountThreads>;
  __shared__ typename Reduce::TempStorage temp;
  unsigned long long mine = 0;
  for (uint64_t c = static_cast<uint64_t>(blockIdx.x) * kCountThreads + threadIdx.x; c < chunks;
       c += static_cast<uint64_t>(gridDim.x) * kCountThreads)
    mine += chunk_total[c];
  const unsigned long long sum = Reduce(temp).Sum(mine);
  if (threadIdx.x != 0) return;
  if (sum > 0) atomicAdd(counts, sum);
  if (blockIdx.x == 0) counts[1] = *visible;
}

// A block per slot chunk of the walk: each slot's end in the list, its slot chunk's start + the
// inclusive sum of tiles_touched over the slot chunk up to it. A slot chunk without entries
// (nothing listed) is left alone: emission skips it too.
__global__ void __launch_bounds__(fm::kChunkSize)
    gaussian_ends_kernel(const uint32_t* __restrict__ tiles_touched,  // [S]
                         const uint32_t* __restrict__ chunk_total,    // [SC]
                         const uint64_t* __restrict__ chunk_start,    // [SC]
                         uint64_t n, ChunkWalk walk,
                         uint64_t* __restrict__ ends) {  // [S]
  using Scan = cub::BlockScan<uint32_t, fm::kChunkSize>;
  __shared__ typename Scan::TempStorage scratch;
  const uint64_t chunks = walk.size();
  for (uint64_t k = blockIdx.x; k < chunks; k += gridDim.x) {
    if (chunk_total[k] == 0u) continue;  // block-uniform
    const uint64_t i = k * fm::kChunkSize + threadIdx.x;
    const uint32_t touched = i < n ? tiles_touched[i] : 0u;
    uint32_t upto = 0;
    Scan(scratch).InclusiveSum(touched, upto);
    if (i < n) ends[i] = chunk_start[k] + upto;
    __syncthreads();  // scratch is reused next round
  }
}

// Calls emit(j) for this thread's walk positions: with an `order`, the thread's index in the grid
// (j indexes the order); without, thread x of each walked slot chunk k that has entries (j = the
// slot, k * kChunkSize + x; the chunk test is block-uniform, so warps stay whole).
template <typename Emit>
__device__ __forceinline__ void for_each_walked(const uint32_t* order, const ChunkWalk& walk,
                                                const uint32_t* __restrict__ chunk_total, Emit&& emit) {
  if (order) {
    emit(static_cast<uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x);
    return;
  }
  const uint64_t chunks = walk.size();
  for (uint64_t k = blockIdx.x; k < chunks; k += gridDim.x)
    if (chunk_total[k] != 0u) emit(k * fm::kChunkSize + threadIdx.x);
}

// One thread per Gaussian writes its run of keys, testing each tile of its rectangle (vanilla
// lists, and any list counted without masks; exact lists and catgs trails with tile masks go to
// emit_mask_keys_kernel). Writes are bounded by
// its own slot [begin, end): a disagreement between counting and emitting could never spill into
// a neighbour. Thread j takes Gaussian order[j] when an order is given, else Gaussian j.
__device__ __forceinline__ void emit_gaussian_keys(uint64_t j, const uint32_t* __restrict__ order,  // [n] or null
                                                   const TileTests& tests,
                                                   const float* __restrict__ depth,             // [N]
                                                   const ushort4* __restrict__ rect,            // [N]
                                                   const uint32_t* __restrict__ tiles_touched,  // [N]
                                                   const uint64_t* __restrict__ ends,           // [N] end of each run
                                                   uint64_t n, uint64_t gaussians, int tiles_x, int tiles_y,
                                                   const KeyOut& keys, uint32_t* __restrict__ values) {  // [L]
  if (j >= n) return;
  const uint64_t i = order ? order[j] : j;
  if (i >= gaussians || tiles_touched[i] == 0) return;  // (depth_order's padding index is N)
  const ushort4 r = rect[i];
  if ((r.z - r.x) * (r.w - r.y) > tune::kBigRectTiles) return;  // emit_big_kernel's
  const uint64_t end = ends[i];
  uint64_t at = end - tiles_touched[i];
  const uint32_t depth_bits = keys.needs_depth() ? __float_as_uint(depth[i]) : 0u;
  const GaussianTileTest hit = load_tile_test(tests, i);
  for (int ty = r.y; ty < r.w && at < end; ++ty) {
    for (int tx = r.x; tx < r.z && at < end; ++tx) {
      if (!hit(tx, ty)) continue;
      keys.put(at, static_cast<uint32_t>(ty * tiles_x + tx), depth_bits);
      values[at] = static_cast<uint32_t>(i);
      ++at;
    }
  }
  // Unfilled slots (counting said more than emission found: never expected) become sentinels.
  const auto sentinel = static_cast<uint32_t>(tiles_x * tiles_y);
  for (; at < end; ++at) {
    keys.put(at, sentinel, 0xffffffffu);
    values[at] = static_cast<uint32_t>(i);
  }
}

// Thread j of the walk (`order` given) or of each walked chunk with entries (index order).
__global__ void __launch_bounds__(tune::kGaussianThreads)
    emit_keys_kernel(const uint32_t* __restrict__ order,  // [n] or null
                     TileTests tests,
                     const float* __restrict__ depth,             // [N]
                     const ushort4* __restrict__ rect,            // [N]
                     const uint32_t* __restrict__ tiles_touched,  // [N]
                     const uint64_t* __restrict__ ends,           // [N] end of each Gaussian's run
                     const uint32_t* __restrict__ chunk_total,    // [chunks], with no order
                     ChunkWalk walk, uint64_t n, uint64_t gaussians, int tiles_x, int tiles_y, KeyOut keys,
                     uint32_t* __restrict__ values) {  // [L]
  for_each_walked(order, walk, chunk_total, [&](uint64_t j) {
    emit_gaussian_keys(j, order, tests, depth, rect, tiles_touched, ends, n, gaussians, tiles_x, tiles_y, keys, values);
  });
}

// Position of the r-th set bit (r from 0) of mask, r < popc(mask): a binary search on popc.
__device__ __forceinline__ int nth_set_bit(uint32_t mask, uint32_t r) {
  int pos = 0;
  for (int w = 16; w > 0; w >>= 1) {
    const auto low = static_cast<uint32_t>(__popc(mask & ((1u << w) - 1u)));
    if (r >= low) {
      r -= low;
      mask >>= w;
      pos += w;
    }
  }
  return pos;
}

// Small catgs trails and exact ellipses (tests.trails.tile_mask, Projected::tile_mask: the tile
// test's answers, kept when the tiles were counted), a warp per 32 consecutive Gaussians of the
// walk. Their runs are adjacent in the list
// (ends is the running sum in walk order), so the warp writes its whole span with its lanes on
// consecutive slots: each store is one coalesced line. A thread per Gaussian writing its own run
// made every store touch 32 scattered sectors (ncu: tests/gpu/RESULTS.md, "Where the tuned
// defaults come from": coalesced key emission). Slot s belongs to the last lane whose
// run starts at or before s (a binary search over the lanes' run starts by shuffles); its rank
// r = s - start picks the r-th set bit of that lane's mask, i.e. the r-th listed tile in
// row-major order, as a per-Gaussian loop writes them. Big Gaussians' slots are left to
// emit_big_kernel. Every thread of a warp must reach the shuffles: no early return.
__device__ __forceinline__ void emit_mask_keys_warp(uint64_t j, const uint32_t* __restrict__ order,  // [n] or null
                                                    const uint32_t* __restrict__ tile_mask,          // [N]
                                                    const float* __restrict__ depth,                 // [N]
                                                    const ushort4* __restrict__ rect,                // [N]
                                                    const uint32_t* __restrict__ tiles_touched,      // [N]
                                                    const uint64_t* __restrict__ ends,               // [N]
                                                    uint64_t n, uint64_t gaussians, int tiles_x, int tiles_y,
                                                    const KeyOut& keys, uint32_t* __restrict__ values) {  // [L]
  constexpr unsigned kAll = 0xffffffffu;
  const auto lane = static_cast<int>(threadIdx.x & 31u);
  // This lane's run [start, end). Lanes past the walk (or the depth order's padding) get a run
  // that starts after every slot, so no search lands on them; starts rise with the lane.
  uint64_t start = ~0ull, end = 0;
  uint32_t i = 0, mask = 0, corner = 0, depth_bits = 0;
  int width = 1;
  bool small = false;
  if (j < n) {
    const uint64_t g = order ? order[j] : j;
    if (g < gaussians) {
      i = static_cast<uint32_t>(g);
      end = ends[i];
      const uint32_t count = tiles_touched[i];
      start = end - count;
      if (count > 0) {
        const ushort4 r = rect[i];
        width = r.z - r.x;
        small = width * (r.w - r.y) <= tune::kBigRectTiles;
        corner = static_cast<uint32_t>(r.x) | (static_cast<uint32_t>(r.y) << 16);
        if (small) mask = tile_mask[i];
        if (small && keys.needs_depth()) depth_bits = __float_as_uint(depth[i]);
      }
    }
  }
  const uint64_t first = __shfl_sync(kAll, start, 0);
  uint64_t last = end;
  for (int off = 16; off > 0; off >>= 1) {
    const uint64_t other = __shfl_xor_sync(kAll, last, off);
    last = other > last ? other : last;
  }
  const auto sentinel = static_cast<uint32_t>(tiles_x * tiles_y);
  for (uint64_t base = first; base < last;) {  // warp-uniform
    const uint64_t s = base + static_cast<uint64_t>(lane);
    int owner = 0;
    for (int step = 16; step > 0; step >>= 1)
      if (__shfl_sync(kAll, start, owner + step) <= s) owner += step;
    const uint64_t owner_start = __shfl_sync(kAll, start, owner);
    const uint32_t owner_mask = __shfl_sync(kAll, mask, owner);
    const uint32_t owner_corner = __shfl_sync(kAll, corner, owner);
    const uint32_t owner_index = __shfl_sync(kAll, i, owner);
    const uint32_t owner_depth = __shfl_sync(kAll, depth_bits, owner);
    const int owner_width = __shfl_sync(kAll, width, owner);
    const bool owner_small = __shfl_sync(kAll, static_cast<int>(small), owner) != 0;
    // A window that starts in a big Gaussian's run (emit_big_kernel writes it) jumps to the run's
    // end: a near Gaussian's thousands of slots held the warp for a round per 32 of them.
    const int head = __shfl_sync(kAll, owner, 0);
    const uint64_t head_end = __shfl_sync(kAll, end, head);
    if (!__shfl_sync(kAll, static_cast<int>(owner_small), 0) && head_end > base) {
      base = head_end;
      continue;
    }
    base += 32;
    if (s >= last || !owner_small) continue;
    const auto rank = static_cast<uint32_t>(s - owner_start);
    if (rank < static_cast<uint32_t>(__popc(owner_mask))) {
      const int b = nth_set_bit(owner_mask, rank);
      const uint32_t tx = (owner_corner & 0xffffu) + static_cast<uint32_t>(b % owner_width);
      const uint32_t ty = (owner_corner >> 16) + static_cast<uint32_t>(b / owner_width);
      keys.put(s, ty * static_cast<uint32_t>(tiles_x) + tx, owner_depth);
    } else {  // counting said more than the mask holds: never expected
      keys.put(s, sentinel, 0xffffffffu);
    }
    values[s] = owner_index;
  }
}

// Thread j of the walk (`order` given) or of each walked chunk with entries (index order).
__global__ void __launch_bounds__(tune::kGaussianThreads)
    emit_mask_keys_kernel(const uint32_t* __restrict__ order,          // [n] or null
                          const uint32_t* __restrict__ tile_mask,      // [N]
                          const float* __restrict__ depth,             // [N]
                          const ushort4* __restrict__ rect,            // [N]
                          const uint32_t* __restrict__ tiles_touched,  // [N]
                          const uint64_t* __restrict__ ends,           // [N]
                          const uint32_t* __restrict__ chunk_total,    // [chunks], with no order
                          ChunkWalk walk, uint64_t n, uint64_t gaussians, int tiles_x, int tiles_y, KeyOut keys,
                          uint32_t* __restrict__ values) {  // [L]
  for_each_walked(order, walk, chunk_total, [&](uint64_t j) {
    emit_mask_keys_warp(j, order, tile_mask, depth, rect, tiles_touched, ends, n, gaussians, tiles_x, tiles_y, keys,
                        values);
  });
}

// Big Gaussians (preprocess.cu count_big_kernel's two passes): a warp per big Gaussian, then a
// block per part of a huge one (huge_parts, tile_test.cuh). Either walks its tiles in row-major
// order, a round of 32 (or kBigThreads) tiles at a time, and the threads whose tile passes take
// consecutive slots (ballot + popc, and across a block's warps their counts' prefix), so the
// order is the one the per-thread loop (and the CPU reference) produces: a part's slots start
// after the entries its Gaussian's earlier parts counted (BigList::part_count).
__global__ void __launch_bounds__(tune::kBigThreads) emit_big_kernel(BigList big, TileTests tests,
                                                                     const float* __restrict__ depth,             // [N]
                                                                     const ushort4* __restrict__ rect,            // [N]
                                                                     const uint32_t* __restrict__ tiles_touched,  // [N]
                                                                     const uint64_t* __restrict__ ends,           // [N]
                                                                     int tiles_x, int tiles_y, KeyOut keys,
                                                                     uint32_t* __restrict__ values) {  // [L]
  constexpr int kWarps = tune::kBigThreads / 32;
  __shared__ uint32_t warp_hits[kWarps];
  const unsigned lane = threadIdx.x & 31u, warp = threadIdx.x / 32u;
  const unsigned warps = gridDim.x * (blockDim.x / 32u);
  const auto sentinel = static_cast<uint32_t>(tiles_x * tiles_y);
  for (unsigned w = (blockIdx.x * blockDim.x + threadIdx.x) / 32u; w < big.count[0]; w += warps) {
    const uint32_t i = big.index[w];
    const uint32_t touched = tiles_touched[i];
    const ushort4 r = rect[i];
    const int rw = r.z - r.x, area = rw * (r.w - r.y);
    if (touched == 0) continue;  // warp-uniform
    const uint64_t end = ends[i];
    uint64_t at = end - touched;
    const uint32_t depth_bits = __float_as_uint(depth[i]);
    const GaussianTileTest test = load_tile_test(tests, i);
    for (int base = 0; base < area && at < end; base += 32) {
      const int t = base + static_cast<int>(lane);
      const int tx = r.x + (t % rw), ty = r.y + (t / rw);
      const bool hit = t < area && test(tx, ty);
      const unsigned hits = __ballot_sync(0xffffffffu, hit);
      const uint64_t slot = at + static_cast<uint64_t>(__popc(hits & ((1u << lane) - 1u)));
      if (hit && slot < end) {
        keys.put(slot, static_cast<uint32_t>(ty * tiles_x + tx), depth_bits);
        values[slot] = i;
      }
      at += static_cast<uint64_t>(__popc(hits));
    }
    for (uint64_t s = at + lane; s < end; s += 32) {  // never expected, as in emit_keys_kernel
      keys.put(s, sentinel, 0xffffffffu);
      values[s] = i;
    }
  }
  const uint64_t items = static_cast<uint64_t>(big.count[1]) * tune::kHugeParts;  // (huge one, part)
  for (uint64_t item = blockIdx.x; item < items; item += gridDim.x) {
    const auto h = static_cast<unsigned>(item / tune::kHugeParts);
    const int p = static_cast<int>(item % tune::kHugeParts);
    const uint32_t i = big.huge(h);
    const uint32_t touched = tiles_touched[i];
    const ushort4 r = rect[i];
    const int rw = r.z - r.x, area = rw * (r.w - r.y);
    // A square test (vanilla) had no count pass: one part, as its runs need no counts.
    const int parts = tests.kind == TileTestKind::square ? 1 : huge_parts(big, h, area);
    if (touched == 0 || p >= parts) continue;  // block-uniform
    // This part's slots [at, end): after its Gaussian's earlier parts' entries.
    uint64_t at = ends[i] - touched, end = ends[i];
    if (parts > 1) {
      const uint32_t* counts = big.part_count + static_cast<uint64_t>(h) * tune::kHugeParts;
      for (int q = 0; q < p; ++q) at += counts[q];
      end = at + counts[p];
    }
    const uint32_t depth_bits = __float_as_uint(depth[i]);
    const GaussianTileTest test = load_tile_test(tests, i);
    const int last = huge_part_first(p + 1, parts, area);
    for (int base = huge_part_first(p, parts, area); base < last && at < end; base += static_cast<int>(blockDim.x)) {
      const int t = base + static_cast<int>(threadIdx.x);
      const int tx = r.x + (t % rw), ty = r.y + (t / rw);
      const bool hit = t < last && test(tx, ty);
      const unsigned hits = __ballot_sync(0xffffffffu, hit);
      if (lane == 0) warp_hits[warp] = static_cast<uint32_t>(__popc(hits));
      __syncthreads();
      uint64_t before = 0, round = 0;  // hits of the warps before this one, and of the block
      for (unsigned k = 0; k < kWarps; ++k) {
        before += k < warp ? warp_hits[k] : 0u;
        round += warp_hits[k];
      }
      const uint64_t slot = at + before + static_cast<uint64_t>(__popc(hits & ((1u << lane) - 1u)));
      if (hit && slot < end) {
        keys.put(slot, static_cast<uint32_t>(ty * tiles_x + tx), depth_bits);
        values[slot] = i;
      }
      at += round;
      __syncthreads();  // warp_hits is rewritten next round
    }
    for (uint64_t s = at + threadIdx.x; s < end; s += blockDim.x) {  // never expected
      keys.put(s, sentinel, 0xffffffffu);
      values[s] = i;
    }
  }
}

}  // namespace

std::size_t scan_temp_bytes(uint64_t chunks) {
  std::size_t bytes = 0;
  WideCounts in(nullptr, WidenToU64{});
  CATGS_CUDA(cub::DeviceScan::ExclusiveSum(nullptr, bytes, in, static_cast<uint64_t*>(nullptr), chunks));
  return bytes;
}

void count_list(const Projected& p, uint64_t n, const unsigned long long* visible, unsigned long long* counts,
                cudaStream_t stream) {
  const uint64_t chunks = fm::chunk_count(n);
  // One block per 16 k chunks (4 M Gaussians), at most 32: each sums a few thousand counts.
  const auto blocks = static_cast<unsigned>(std::min<uint64_t>(32, chunks / (16 * kCountThreads) + 1));
  count_list_kernel<<<blocks, kCountThreads, 0, stream>>>(p.chunk_total, chunks, visible, counts);
  CATGS_CUDA_LAUNCHED("count_list_kernel");
}

void scan_chunks(const Projected& p, uint64_t n, uint64_t* chunk_start, void* temp, std::size_t temp_bytes,
                 cudaStream_t stream) {
  const uint64_t chunks = fm::chunk_count(n);
  if (chunks == 0) return;
  WideCounts in(p.chunk_total, WidenToU64{});
  CATGS_CUDA(cub::DeviceScan::ExclusiveSum(temp, temp_bytes, in, chunk_start, chunks, stream));
}

void gaussian_ends(const Projected& p, uint64_t n, const ChunkWalk& walk, const uint64_t* chunk_start, uint64_t* ends,
                   cudaStream_t stream) {
  const uint64_t blocks = walk.blocks();
  if (blocks == 0) return;
  if (blocks > 0x7fffffffull) throw std::length_error("gaussian_ends: too many chunks for one grid");
  gaussian_ends_kernel<<<static_cast<unsigned>(blocks), fm::kChunkSize, 0, stream>>>(p.tiles_touched, p.chunk_total,
                                                                                     chunk_start, n, walk, ends);
  CATGS_CUDA_LAUNCHED("gaussian_ends_kernel");
}

void emit_keys(const Projected& p, const uint64_t* ends, uint64_t n, const ChunkWalk& chunks, const CameraParams& cam,
               const TileTests& tests, const BigList& big, uint64_t* wide_keys, uint32_t* narrow_keys,
               DepthKeyPacking packing, uint32_t* values, const uint32_t* order, uint64_t order_count,
               cudaStream_t stream) {
  if (n == 0) return;
  const KeyOut keys{wide_keys, narrow_keys, packing};
  const uint64_t walk = order ? order_count : n;
  // A thread per Gaussian of the order, or a block per walked chunk.
  const uint64_t blocks = order ? (walk + tune::kGaussianThreads - 1) / tune::kGaussianThreads : chunks.blocks();
  if (blocks > 0x7fffffffull) throw std::length_error("emit_keys: too many Gaussians for one grid");
  // The small Gaussians' tile answers, where the counting kept them (trails; exact ellipses).
  const uint32_t* mask = tests.kind == TileTestKind::trail     ? tests.trails.tile_mask
                         : tests.kind == TileTestKind::ellipse ? p.tile_mask
                                                               : nullptr;
  if (walk > 0 && mask) {
    emit_mask_keys_kernel<<<static_cast<unsigned>(blocks), tune::kGaussianThreads, 0, stream>>>(
        order, mask, p.depth, p.rect, p.tiles_touched, ends, p.chunk_total, chunks, walk, n, cam.tiles_x, cam.tiles_y,
        keys, values);
    CATGS_CUDA_LAUNCHED("emit_mask_keys_kernel");
  } else if (walk > 0) {
    emit_keys_kernel<<<static_cast<unsigned>(blocks), tune::kGaussianThreads, 0, stream>>>(
        order, tests, p.depth, p.rect, p.tiles_touched, ends, p.chunk_total, chunks, walk, n, cam.tiles_x, cam.tiles_y,
        keys, values);
    CATGS_CUDA_LAUNCHED("emit_keys_kernel");
  }
  emit_big_kernel<<<tune::kBigBlocks, tune::kBigThreads, 0, stream>>>(big, tests, p.depth, p.rect, p.tiles_touched,
                                                                      ends, cam.tiles_x, cam.tiles_y, keys, values);
  CATGS_CUDA_LAUNCHED("emit_big_kernel");
}

}  // namespace catgs::cuda::stages
