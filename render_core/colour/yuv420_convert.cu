// Colour conversion of a rendered frame, RGBA8 -> BT.709 limited-range I420, on the GPU
// (colour/bt709.h's formula, shared with rgba_to_yuv420_bt709 in colour/yuv420.cpp, compiled
// without FMA contraction so every code value matches the CPU reference).
// Runs after rasterization on the renderer's stream, so a frame that stays on the GPU never
// crosses to the host as RGBA (docs/DESIGN.md "Data flow of a frame"; issue 5).
#include "base/cuda_check.h"
#include "colour/bt709.h"
#include "colour/yuv420_convert.h"

namespace catgs::cuda::stages {

namespace {

// One thread per 2x2 block: four Y samples and one Cb, Cr pair.
__global__ void rgba8_to_yuv420_kernel(const uint32_t* __restrict__ rgba8, int width, int height, Yuv420Pitched out) {
  const int bx = blockIdx.x * blockDim.x + threadIdx.x;
  const int by = blockIdx.y * blockDim.y + threadIdx.y;
  const int c = 2 * bx, r = 2 * by;
  if (c >= width || r >= height) return;
  double sum[3] = {0, 0, 0};
  for (int dr = 0; dr < 2; ++dr) {
    uint8_t* y_row = out.y + static_cast<size_t>(r + dr) * out.y_pitch;
    for (int dc = 0; dc < 2; ++dc) {
      const uint32_t p = rgba8[static_cast<size_t>(r + dr) * width + c + dc];
      const double R = (p & 0xffu) / 255.0, G = ((p >> 8) & 0xffu) / 255.0, B = ((p >> 16) & 0xffu) / 255.0;
      y_row[c + dc] = bt709::luma(R, G, B);
      sum[0] += R;
      sum[1] += G;
      sum[2] += B;
    }
  }
  const double R = sum[0] / 4, G = sum[1] / 4, B = sum[2] / 4;
  out.u[static_cast<size_t>(by) * out.u_pitch + bx] = bt709::cb(R, G, B);
  out.v[static_cast<size_t>(by) * out.v_pitch + bx] = bt709::cr(R, G, B);
}

}  // namespace

void rgba8_to_yuv420(const uint32_t* rgba8, int width, int height, const Yuv420Pitched& out, cudaStream_t stream) {
  const dim3 block(32, 8);
  const dim3 grid((width / 2 + block.x - 1) / block.x, (height / 2 + block.y - 1) / block.y);
  rgba8_to_yuv420_kernel<<<grid, block, 0, stream>>>(rgba8, width, height, out);
  CATGS_CUDA(cudaGetLastError());
}

}  // namespace catgs::cuda::stages
