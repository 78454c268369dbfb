// Colour conversion on the GPU (yuv420_convert.cu; mirrors colour/yuv420.cpp).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include <cuda_runtime.h>

namespace catgs::cuda::stages {

// I420 planes in device memory (pitches in bytes), written by rgba8_to_yuv420.
struct Yuv420Pitched {
  uint8_t* y;
  size_t y_pitch;
  uint8_t* u;
  size_t u_pitch;
  uint8_t* v;
  size_t v_pitch;
};

// After stage 5 (yuv420_convert.cu; mirrors rgba_to_yuv420_bt709 of catgs/yuv420.h): the packed
// RGBA8 image [height, width] -> BT.709 limited-range I420 (Y per pixel, Cb/Cr from each 2x2
// mean). width and height must be even. One thread per 2x2 block.
void rgba8_to_yuv420(const uint32_t* rgba8, int width, int height, const Yuv420Pitched& out, cudaStream_t stream);

}  // namespace catgs::cuda::stages
