// Occlusion culling's two small stages (forward_model/occlusion.h; mirror cpu/occlusion_map.cpp),
// a thread per tile: after rasterization, the map from the rasterizer's opaque points (one atomic
// per tile with entries behind); before pre-processing, the last map reprojected onto this
// frame's tiles.
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

__global__ void __launch_bounds__(tune::kGaussianThreads)
    occlusion_reproject_kernel(fm::OcclusionMap map, fm::View now, int tiles_x, int tiles,
                               float* __restrict__ now_depth) {
  const int t = static_cast<int>(blockIdx.x * blockDim.x + threadIdx.x);
  if (t >= tiles) return;
  now_depth[t] = fm::reprojected_tile_depth(map, now, t % tiles_x, t / tiles_x);
}

}  // namespace

void occlusion_reproject(const fm::OcclusionMap& map, const CameraParams& cam, float* now_depth, cudaStream_t stream) {
  const int tiles = cam.tiles_x * cam.tiles_y;
  if (tiles <= 0) return;
  occlusion_reproject_kernel<<<(tiles + tune::kGaussianThreads - 1) / tune::kGaussianThreads, tune::kGaussianThreads, 0,
                               stream>>>(map, static_cast<const fm::View&>(cam), cam.tiles_x, tiles, now_depth);
  CATGS_CUDA_LAUNCHED("occlusion_reproject_kernel");
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
