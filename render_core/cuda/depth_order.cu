// Stage 2a' (optional, CudaOptions::depth_first_sort): the depth-first order of the render
// list. The list must end up sorted by the plain [tile | depth] key, ties in Gaussian index order
// (forward_model/key_packing.h, cpu/sort.cpp). Sorting its L entries on 64-bit keys visits 32 +
// tile bits (6 radix passes at 1080p). Instead the V visible Gaussians are sorted by depth once (32-bit keys, V << L), each
// Gaussian's slot in the list is handed out in that order, and the L entries are then sorted
// stably on their tile alone (13 bits at 1080p: 2 passes). A stable sort by tile of a list in
// (depth, index) order is the plain [tile | depth] order with index ties: the same list, entry
// for entry, as a single sort on plain keys (catgs key frames; GPU test row `depthsort`). The
// exact pipeline's single sort uses the 32-bit key, which ties depths within its quantum. It pays where lists are long: a catgs key
// frame's trail list is several times the exact list (tests/gpu/RESULTS.md, "Where the tuned
// defaults come from": the depth-first sort).
#include <algorithm>

#include <cub/device/device_scan.cuh>
#include <cub/device/device_select.cuh>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/permutation_iterator.h>
#include <thrust/iterator/transform_iterator.h>

#include "base/cuda_check.h"
#include "depth_order.h"
#include "sort.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

// Both read tiles_touched through listed_tiles: a chunk that exact pre-processing culled left
// its Gaussians' counts unwritten (records.h).
struct IsVisible {
  const uint32_t* tiles_touched;  // [N]
  const uint32_t* chunk_total;    // [chunks]
  __device__ bool operator()(uint32_t i) const { return listed_tiles(tiles_touched, chunk_total, i) > 0; }
};

struct TouchedOf {  // Gaussian index -> its tile count, widened for the 64-bit scan
  const uint32_t* tiles_touched;
  const uint32_t* chunk_total;
  uint64_t n;  // index n: a padding slot (gather_depth_keys_kernel), no tiles
  __device__ uint64_t operator()(uint32_t i) const { return i < n ? listed_tiles(tiles_touched, chunk_total, i) : 0u; }
};

using CountsInDepthOrder = thrust::transform_iterator<TouchedOf, const uint32_t*, uint64_t>;
using EndsByGaussian = thrust::permutation_iterator<uint64_t*, const uint32_t*>;

// Depth keys of the visible Gaussians: the bits of a positive float order like the float
// (every visible depth is past the near plane). The host's V (the pre-processing count) and the
// selected count are the same number; should they ever differ, the slots past the selection
// become padding (index n, last in depth order, no tiles, its end written to the spare ends[n]).
__global__ void __launch_bounds__(tune::kGaussianThreads)
    gather_depth_keys_kernel(uint32_t* visible_index,  // [V]
                             const unsigned* count,    // [1] selected
                             uint32_t visible,         // V
                             const float* depth,       // [N]
                             uint32_t n,
                             uint32_t* keys) {  // [V]
  const uint32_t j = blockIdx.x * blockDim.x + threadIdx.x;
  if (j >= visible) return;
  if (j < *count) {
    keys[j] = __float_as_uint(depth[visible_index[j]]);
  } else {
    keys[j] = 0xffffffffu;
    visible_index[j] = n;
  }
}

}  // namespace

std::size_t depth_order_temp_bytes(uint64_t n) {
  // The three CUB calls run one after another on one stream: they share one scratch buffer.
  std::size_t select = 0, sort = 0, scan = 0;
  CATGS_CUDA(cub::DeviceSelect::If(nullptr, select, thrust::counting_iterator<uint32_t>(0),
                                   static_cast<uint32_t*>(nullptr), static_cast<unsigned*>(nullptr),
                                   static_cast<int64_t>(n), IsVisible{nullptr, nullptr}));
  // The sort's offsets follow its count (sort.cu), which is V <= N at run time: size for both.
  sort = std::max(sort_narrow_temp_bytes(n, 32), sort_narrow_temp_bytes(std::min<uint64_t>(n, 0x7fffffffull), 32));
  CountsInDepthOrder in(nullptr, TouchedOf{nullptr, nullptr, 0});
  EndsByGaussian out(nullptr, nullptr);
  CATGS_CUDA(cub::DeviceScan::InclusiveSum(nullptr, scan, in, out, static_cast<int64_t>(n)));
  return std::max(select, std::max(sort, scan));
}

const uint32_t* depth_order_ends(const uint32_t* tiles_touched, const uint32_t* chunk_total, const float* depth,
                                 uint64_t n, uint64_t visible, const DepthOrderBuffers& b, uint64_t* ends,
                                 cudaStream_t stream) {
  if (visible == 0) return b.index[0];
  std::size_t temp_bytes = b.temp_bytes;  // CUB takes it by reference
  CATGS_CUDA(cub::DeviceSelect::If(b.temp, temp_bytes, thrust::counting_iterator<uint32_t>(0), b.index[0], b.count,
                                   static_cast<int64_t>(n), IsVisible{tiles_touched, chunk_total}, stream));
  const auto blocks = static_cast<unsigned>((visible + tune::kGaussianThreads - 1) / tune::kGaussianThreads);
  gather_depth_keys_kernel<<<blocks, tune::kGaussianThreads, 0, stream>>>(
      b.index[0], b.count, static_cast<uint32_t>(visible), depth, static_cast<uint32_t>(n), b.keys[0]);
  CATGS_CUDA_LAUNCHED("gather_depth_keys_kernel");
  // Stable: equal depths keep index order, as the single [tile | depth] sort keeps them.
  uint32_t* k[2] = {b.keys[0], b.keys[1]};
  uint32_t* v[2] = {b.index[0], b.index[1]};
  const int half = sort_pairs_narrow(k, v, visible, 32, b.temp, temp_bytes, stream);
  // Each Gaussian's end slot: the running sum of the tile counts in depth order, written back
  // at the Gaussian's own index (what emit_keys reads). Invisible Gaussians keep theirs: they
  // emit nothing.
  const uint32_t* order = v[half];
  CountsInDepthOrder in(order, TouchedOf{tiles_touched, chunk_total, n});
  EndsByGaussian out(ends, order);
  CATGS_CUDA(cub::DeviceScan::InclusiveSum(b.temp, temp_bytes, in, out, static_cast<int64_t>(visible), stream));
  return order;
}

}  // namespace catgs::cuda::stages
