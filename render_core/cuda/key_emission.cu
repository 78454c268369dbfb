// Stage 2: render-list key emission (mirrors src/cpu/key_emission.cpp). Offsets come from a device
// scan of the per-Gaussian tile counts, so no Gaussian ever touches a shared counter (DESIGN.md:
// FlashGS's contended global atomicAdd per Gaussian is what slows it on the city). Built with
// -fmad=false, like pre-processing, so the exact tile test here answers exactly as it did when
// the tiles were counted.
#include <cub/device/device_scan.cuh>
#include <thrust/iterator/transform_iterator.h>

#include "cuda_check.h"
#include "stages.h"
#include "tile_test.cuh"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

struct WidenToU64 {
  __host__ __device__ uint64_t operator()(uint32_t v) const { return v; }
};

using WideCounts = thrust::transform_iterator<WidenToU64, const uint32_t*, uint64_t>;

// Where a key goes: [tile | depth bits] into `wide`, or (depth-first sort, depth_order.cu) the
// tile id alone into `tile_only` when that is not null. The choice is uniform over a launch.
struct KeyOut {
  uint64_t* wide;       // [L]
  uint32_t* tile_only;  // [L] or null
  __device__ void put(uint64_t at, uint32_t tile, uint32_t depth_bits) const {
    if (tile_only)
      tile_only[at] = tile;
    else
      wide[at] = (static_cast<uint64_t>(tile) << 32) | depth_bits;
  }
};

// counts[0] = render list length (ends[n-1]), counts[1] = visible Gaussians: one 16-byte readback.
__global__ void gather_counts_kernel(const uint64_t* ends,           // [n]
                                     uint64_t n,
                                     const unsigned long long* visible,  // [1]
                                     unsigned long long* counts) {       // [2]
  counts[0] = n > 0 ? ends[n - 1] : 0ull;
  counts[1] = *visible;
}

// One thread per Gaussian writes its run of keys. Writes are bounded by its own slot
// [begin, end): a disagreement between counting and emitting could never spill into a neighbour.
// Thread j takes Gaussian order[j] when an order is given (the depth-first sort: its slots follow
// that order, so neighbouring threads write neighbouring slots), else Gaussian j.
__global__ void __launch_bounds__(tune::kGaussianThreads)
emit_keys_kernel(const uint32_t* order,         // [n] or null
                 TileTests tests,
                 const float* depth,            // [N]
                 const ushort4* rect,           // [N]
                 const uint32_t* tiles_touched, // [N]
                 const uint64_t* ends,          // [N] end of each Gaussian's run
                 uint64_t n, uint64_t gaussians, int tiles_x, int tiles_y,
                 KeyOut keys,
                 uint32_t* values) {            // [L]
  const uint64_t j = static_cast<uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (j >= n) return;
  const uint64_t i = order ? order[j] : j;
  if (i >= gaussians || tiles_touched[i] == 0) return;  // (depth_order's padding index is N)
  const ushort4 r = rect[i];
  if ((r.z - r.x) * (r.w - r.y) > tune::kBigRectTiles) return;  // emit_big_kernel's
  const uint64_t end = ends[i];
  uint64_t at = end - tiles_touched[i];
  const uint32_t depth_bits = keys.tile_only ? 0u : __float_as_uint(depth[i]);  // tile keys need no depth
  if (tests.kind == TileTestKind::trail && tests.trails.tile_mask) {
    // The trail tests ran when the tiles were counted: emit the set bits, row-major as below.
    const int rw = r.z - r.x;
    for (uint32_t mask = tests.trails.tile_mask[i]; mask != 0u && at < end; mask &= mask - 1u, ++at) {
      const int b = __ffs(static_cast<int>(mask)) - 1;
      const auto tile = static_cast<uint32_t>((r.y + b / rw) * tiles_x + r.x + b % rw);
      keys.put(at, tile, depth_bits);
      values[at] = static_cast<uint32_t>(i);
    }
  } else {
    const GaussianTileTest hit = load_tile_test(tests, i);
    for (int ty = r.y; ty < r.w && at < end; ++ty) {
      for (int tx = r.x; tx < r.z && at < end; ++tx) {
        if (!hit(tx, ty)) continue;
        keys.put(at, static_cast<uint32_t>(ty * tiles_x + tx), depth_bits);
        values[at] = static_cast<uint32_t>(i);
        ++at;
      }
    }
  }
  // Unfilled slots (counting said more than emission found: never expected) become sentinels.
  const auto sentinel = static_cast<uint32_t>(tiles_x * tiles_y);
  for (; at < end; ++at) {
    keys.put(at, sentinel, 0xffffffffu);
    values[at] = static_cast<uint32_t>(i);
  }
}

// Big Gaussians, a warp each: the rectangle is walked 32 tiles at a time in row-major order;
// the lanes whose tile passes take consecutive slots (ballot + popc), so the order is the one the
// per-thread loop (and the CPU reference) produces.
__global__ void __launch_bounds__(tune::kBigThreads)
emit_big_kernel(BigList big, TileTests tests,
                const float* depth,            // [N]
                const ushort4* rect,           // [N]
                const uint32_t* tiles_touched, // [N]
                const uint64_t* ends,          // [N]
                int tiles_x, int tiles_y,
                KeyOut keys,
                uint32_t* values) {            // [L]
  const unsigned lane = threadIdx.x & 31u;
  const unsigned warps = gridDim.x * (blockDim.x / 32u);
  const unsigned total = *big.count;
  const auto sentinel = static_cast<uint32_t>(tiles_x * tiles_y);
  for (unsigned w = (blockIdx.x * blockDim.x + threadIdx.x) / 32u; w < total; w += warps) {
    const uint32_t i = big.index[w];
    const uint32_t touched = tiles_touched[i];
    if (touched == 0) continue;  // warp-uniform
    const uint64_t end = ends[i];
    uint64_t at = end - touched;
    const ushort4 r = rect[i];
    const int rw = r.z - r.x, area = rw * (r.w - r.y);
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
}

}  // namespace

std::size_t scan_temp_bytes(uint64_t n) {
  std::size_t bytes = 0;
  WideCounts in(nullptr, WidenToU64{});
  CATGS_CUDA(cub::DeviceScan::InclusiveSum(nullptr, bytes, in, static_cast<uint64_t*>(nullptr), n));
  return bytes;
}

void scan_tiles_touched(const uint32_t* tiles_touched, uint64_t* ends, uint64_t n, void* temp,
                        std::size_t temp_bytes, const unsigned long long* visible,
                        unsigned long long* counts, cudaStream_t stream) {
  if (n > 0) {
    WideCounts in(tiles_touched, WidenToU64{});
    CATGS_CUDA(cub::DeviceScan::InclusiveSum(temp, temp_bytes, in, ends, n, stream));
  }
  gather_counts_kernel<<<1, 1, 0, stream>>>(ends, n, visible, counts);
  CATGS_CUDA_LAUNCHED("gather_counts_kernel");
}

void emit_keys(const Projected& p, const uint64_t* ends, uint64_t n, const CameraParams& cam,
               const TileTests& tests, const BigList& big, uint64_t* wide_keys, uint32_t* tile_keys,
               uint32_t* values, const uint32_t* order, uint64_t order_count, cudaStream_t stream) {
  if (n == 0) return;
  const KeyOut keys{wide_keys, tile_keys};
  const uint64_t walk = order ? order_count : n;
  const uint64_t blocks = (walk + tune::kGaussianThreads - 1) / tune::kGaussianThreads;
  if (walk > 0)
    emit_keys_kernel<<<static_cast<unsigned>(blocks), tune::kGaussianThreads, 0, stream>>>(
        order, tests, p.depth, p.rect, p.tiles_touched, ends, walk, n, cam.tiles_x, cam.tiles_y, keys, values);
  CATGS_CUDA_LAUNCHED("emit_keys_kernel");
  emit_big_kernel<<<tune::kBigBlocks, tune::kBigThreads, 0, stream>>>(
      big, tests, p.depth, p.rect, p.tiles_touched, ends, cam.tiles_x, cam.tiles_y, keys, values);
  CATGS_CUDA_LAUNCHED("emit_big_kernel");
}

}  // namespace catgs::cuda::stages
