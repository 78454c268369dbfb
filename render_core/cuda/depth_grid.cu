// Stage 5b: the frame's depth grid (forward_model/depth_grid.h; mirrors cpu/depth_grid.cpp).
//
// One warp a vertex: its lanes read 32 entries of the pixel's tile range at once and compute
// their alphas (the gathers and the exponentials, fm::median_walk_alpha), then every lane walks
// the 32 alphas in list order through shuffles (fm::MedianDepthWalk::take: the same serial
// product of 1 - alpha as the CPU's walk, so the two cores agree bit for bit on the same list)
// until the transmittance falls to 0.5. A pixel that never gets there (the sky) reads its whole
// range, 32 entries a round: the single-thread walk it replaced read one dependent gather at a
// time and held every frame for its longest walk (docs/history/shown_picture.md).
#include "base/cuda_check.h"
#include "depth_grid.h"
#include "forward_model/depth_grid.h"

namespace catgs::cuda::stages {

namespace {

constexpr int kWarp = 32;
constexpr unsigned kAllLanes = 0xffffffffu;

__global__ void depth_grid_kernel(const uint2* __restrict__ ranges, const uint32_t* __restrict__ values,
                                  const Splat* __restrict__ splat, const float* __restrict__ depth, int width,
                                  int height, int tiles_x, int cell, int cols, int rows, uint32_t first_tile,
                                  uint32_t end_tile, float* __restrict__ out) {
  const int lane = static_cast<int>(threadIdx.x) % kWarp;
  const int v = static_cast<int>((blockIdx.x * blockDim.x + threadIdx.x) / kWarp);  // the warp's vertex
  if (v >= cols * rows) return;                                                     // the whole warp: v is the warp's
  const int k = v % cols, l = v / cols;
  const int px = fm::depth_grid_pixel(k, cell, width), py = fm::depth_grid_pixel(l, cell, height);
  const auto tile = static_cast<uint32_t>((py / fm::kTileSize) * tiles_x + px / fm::kTileSize);
  if (tile < first_tile || tile >= end_tile) return;  // another pass's tile (the whole warp)
  const uint2 range = ranges[tile];
  fm::MedianDepthWalk walk;
  for (uint32_t base = range.x; base < range.y; base += kWarp) {
    const uint32_t e = base + static_cast<uint32_t>(lane);
    float alpha = 0.0f, z = 0.0f;
    if (e < range.y) {
      const uint32_t s = values[e];
      const Splat sp = splat[s];
      alpha = fm::median_walk_alpha(glm::vec2(sp.mean_ab.x, sp.mean_ab.y),
                                    glm::vec3(sp.mean_ab.z, sp.mean_ab.w, sp.c_opacity_q_log2.x), sp.c_opacity_q_log2.y,
                                    static_cast<float>(px), static_cast<float>(py));
      if (alpha > 0.0f) z = depth[s];
    }
    // Every lane takes the round's alphas in list order: the same products, the same lane
    // crossing, so the loop and its exit stay uniform across the warp.
    const int n = static_cast<int>(min(static_cast<uint32_t>(kWarp), range.y - base));
    bool found = false;
    for (int j = 0; j < n && !found; ++j)
      found = walk.take(__shfl_sync(kAllLanes, alpha, j), __shfl_sync(kAllLanes, z, j));
    if (found) break;
  }
  if (lane == 0) out[v] = walk.depth;
}

}  // namespace

void depth_grid(const uint2* ranges, const uint32_t* sorted_values, const Projected& projected, const CameraParams& cam,
                int cell, uint32_t first_tile, uint32_t end_tile, float* out, cudaStream_t stream) {
  const int cols = fm::depth_grid_cols(cam.width, cell), rows = fm::depth_grid_rows(cam.height, cell);
  constexpr int kThreads = 128;  // four vertices a block
  const long long threads = static_cast<long long>(cols) * rows * kWarp;
  depth_grid_kernel<<<static_cast<unsigned>((threads + kThreads - 1) / kThreads), kThreads, 0, stream>>>(
      ranges, sorted_values, projected.splat, projected.depth, cam.width, cam.height, cam.tiles_x, cell, cols, rows,
      first_tile, end_tile, out);
  CATGS_CUDA_LAUNCHED("depth_grid_kernel");
}

}  // namespace catgs::cuda::stages
