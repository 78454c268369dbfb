// Stage 5b: the frame's depth grid (forward_model/depth_grid.h; mirrors cpu/depth_grid.cpp).
//
// One thread a vertex: it walks its pixel's tile range front to back, one dependent gather of
// the entry's splat and depth at a time, until the transmittance falls to 0.5. A pixel that never
// gets there (the sky) walks its tile's whole range, so the frame waits for the longest walk:
// what the grid costs a frame is in RESULTS.md ("What the visitor's screen shows"). The next step
// is a warp a vertex (32 entries a round, a prefix product of 1 - alpha over the lanes), not yet
// run on a GPU. fm::MedianDepthWalk is the CPU's own code (expf as the CPU reference, not the
// rasterizer's base-2 exponential), so the two cores differ only where the list order does.
#include "base/cuda_check.h"
#include "depth_grid.h"
#include "forward_model/depth_grid.h"

namespace catgs::cuda::stages {

namespace {

__global__ void depth_grid_kernel(const uint2* __restrict__ ranges, const uint32_t* __restrict__ values,
                                  const Splat* __restrict__ splat, const float* __restrict__ depth, int width,
                                  int height, int tiles_x, int cell, int cols, int rows, uint32_t first_tile,
                                  uint32_t end_tile, float* __restrict__ out) {
  const int v = static_cast<int>(blockIdx.x * blockDim.x + threadIdx.x);
  if (v >= cols * rows) return;
  const int k = v % cols, l = v / cols;
  const int px = fm::depth_grid_pixel(k, cell, width), py = fm::depth_grid_pixel(l, cell, height);
  const auto tile = static_cast<uint32_t>((py / fm::kTileSize) * tiles_x + px / fm::kTileSize);
  if (tile < first_tile || tile >= end_tile) return;  // another pass's tile
  const uint2 range = ranges[tile];
  fm::MedianDepthWalk walk;
  for (uint32_t e = range.x; e < range.y; ++e) {
    const uint32_t s = values[e];
    const Splat sp = splat[s];
    if (walk.step(glm::vec2(sp.mean_ab.x, sp.mean_ab.y), glm::vec3(sp.mean_ab.z, sp.mean_ab.w, sp.c_opacity_q_log2.x),
                  sp.c_opacity_q_log2.y, depth[s], static_cast<float>(px), static_cast<float>(py)))
      break;
  }
  out[v] = walk.depth;
}

}  // namespace

void depth_grid(const uint2* ranges, const uint32_t* sorted_values, const Projected& projected, const CameraParams& cam,
                int cell, uint32_t first_tile, uint32_t end_tile, float* out, cudaStream_t stream) {
  const int cols = fm::depth_grid_cols(cam.width, cell), rows = fm::depth_grid_rows(cam.height, cell);
  constexpr int kThreads = 128;
  depth_grid_kernel<<<(cols * rows + kThreads - 1) / kThreads, kThreads, 0, stream>>>(
      ranges, sorted_values, projected.splat, projected.depth, cam.width, cam.height, cam.tiles_x, cell, cols, rows,
      first_tile, end_tile, out);
  CATGS_CUDA_LAUNCHED("depth_grid_kernel");
}

}  // namespace catgs::cuda::stages
