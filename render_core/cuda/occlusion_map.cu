// Occlusion culling's two small stages (forward_model/occlusion.h; mirror cpu/occlusion_map.cpp):
// after rasterization, a thread per tile, the per-tile map from the rasterizer's opaque points (one
// atomic per tile with entries behind); before pre-processing, the last frame's per-pixel map
// reprojected onto this frame: a thread per quad, then a thread per cell of each level.
#include "base/cuda_check.h"
#include "occlusion_map.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

constexpr uint32_t kNever = 0xffffffffu;      // rasterize_slices: no opaque point
constexpr float kNeverDepth = 3.3895314e38f;  // the largest finite float: nothing lies behind it

__global__ void __launch_bounds__(tune::kGaussianThreads)
    occlusion_map_kernel(const uint32_t* __restrict__ opaque_at, const uint2* __restrict__ ranges,
                         const uint32_t* __restrict__ values, const float* __restrict__ depth, uint32_t first_tile,
                         uint32_t end_tile, float* __restrict__ tile_depth, unsigned long long* behind) {
  const uint32_t t = first_tile + blockIdx.x * blockDim.x + threadIdx.x;
  if (t >= end_tile) return;
  const uint32_t P = opaque_at[t];
  const uint2 range = ranges[t];
  if (P == kNever || P == 0u || P > range.y) {
    tile_depth[t] = kNeverDepth;
    return;
  }
  tile_depth[t] = depth[values[P - 1u]];
  if (range.y > P) atomicAdd(behind, static_cast<unsigned long long>(range.y - P));
}

// A thread per quad of the last frame's pixels (x, y) .. (x + 1, y + 1): its pixel centres of this
// frame take its depth where nearer (positive floats order as their bits).
__global__ void __launch_bounds__(tune::kGaussianThreads)
    occlusion_quads_kernel(const float* __restrict__ last_pixels, fm::View last, fm::View now,
                           unsigned* __restrict__ now_pixels) {
  const int q = static_cast<int>(blockIdx.x * blockDim.x + threadIdx.x);
  if (q >= (last.width - 1) * (last.height - 1)) return;
  const int x = q % (last.width - 1), y = q / (last.width - 1);
  int i0, i1, j0, j1;
  float z;
  if (!fm::occlusion_quad(last_pixels, last, now, x, y, &i0, &i1, &j0, &j1, &z)) return;
  const unsigned bits = __float_as_uint(z);
  for (int j = j0; j <= j1; ++j)
    for (int i = i0; i <= i1; ++i) atomicMin(&now_pixels[j * now.width + i], bits);
}

// A thread per cell of level k: the deepest of its pixels (k = 0) or of its 2 x 2 cells of level
// k - 1.
__global__ void __launch_bounds__(tune::kGaussianThreads)
    occlusion_cells_kernel(const float* __restrict__ below, int below_x, int below_y, int width, int height,
                           float* __restrict__ cells, int cells_x, int cells_y, int side) {
  const int c = static_cast<int>(blockIdx.x * blockDim.x + threadIdx.x);
  if (c >= cells_x * cells_y) return;
  const int cx = c % cells_x, cy = c / cells_x;
  const int x1 = min((cx + 1) * side, side == fm::kOcclusionCell ? width : below_x);
  const int y1 = min((cy + 1) * side, side == fm::kOcclusionCell ? height : below_y);
  float deepest = 0.0f;
  for (int y = cy * side; y < y1; ++y)
    for (int x = cx * side; x < x1; ++x) deepest = fmaxf(deepest, below[y * below_x + x]);
  cells[c] = deepest;
}

}  // namespace

fm::OcclusionMap occlusion_reproject(const float* last_pixels, const fm::View& last, const fm::View& now,
                                     unsigned* now_pixels, float* cells, cudaStream_t stream) {
  const fm::OcclusionMap m = fm::occlusion_cells(cells, now.width, now.height);
  const int pixels = now.width * now.height, quads = (last.width - 1) * (last.height - 1);
  // 0x7f7f7f7f: 3.39e38, "no data" (fm::occlusion_quad draws nothing that deep).
  CATGS_CUDA(cudaMemsetAsync(now_pixels, 0x7f, static_cast<std::size_t>(pixels) * sizeof(unsigned), stream));
  if (quads > 0) {
    occlusion_quads_kernel<<<(quads + tune::kGaussianThreads - 1) / tune::kGaussianThreads, tune::kGaussianThreads, 0,
                             stream>>>(last_pixels, last, now, now_pixels);
    CATGS_CUDA_LAUNCHED("occlusion_quads_kernel");
  }
  const float* below = reinterpret_cast<const float*>(now_pixels);
  int below_x = now.width, below_y = now.height;
  for (int k = 0; k < fm::kOcclusionLevels; ++k) {
    const int n = m.cells_x[k] * m.cells_y[k];
    occlusion_cells_kernel<<<(n + tune::kGaussianThreads - 1) / tune::kGaussianThreads, tune::kGaussianThreads, 0,
                             stream>>>(below, below_x, below_y, now.width, now.height, const_cast<float*>(m.cells[k]),
                                       m.cells_x[k], m.cells_y[k], k == 0 ? fm::kOcclusionCell : 2);
    CATGS_CUDA_LAUNCHED("occlusion_cells_kernel");
    below = m.cells[k];
    below_x = m.cells_x[k];
    below_y = m.cells_y[k];
  }
  return m;
}

void occlusion_map(const uint32_t* opaque_at, const uint2* ranges, const uint32_t* values, const Projected& projected,
                   uint32_t first_tile, uint32_t end_tile, float* tile_depth, unsigned long long* behind,
                   cudaStream_t stream) {
  if (end_tile <= first_tile) return;
  const uint32_t n = end_tile - first_tile;
  occlusion_map_kernel<<<(n + tune::kGaussianThreads - 1) / tune::kGaussianThreads, tune::kGaussianThreads, 0,
                         stream>>>(opaque_at, ranges, values, projected.depth, first_tile, end_tile, tile_depth,
                                   behind);
  CATGS_CUDA_LAUNCHED("occlusion_map_kernel");
}

}  // namespace catgs::cuda::stages
