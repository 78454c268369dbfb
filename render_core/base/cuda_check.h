// Checking every CUDA call: a failing call throws catgs::cuda::CudaError naming the call, the
// source line and the CUDA error (code, name, message). In base/ because every room that launches
// CUDA work uses it: the CUDA core (cuda/) and the colour conversion (colour/yuv420_convert.cu).
#pragma once

#include <cuda_runtime.h>

#include "base/cuda_error.h"

namespace catgs::cuda::detail {

[[noreturn]] void throw_cuda_error(cudaError_t err, const char* call, const char* file, int line);

inline void check(cudaError_t err, const char* call, const char* file, int line) {
  if (err != cudaSuccess) throw_cuda_error(err, call, file, line);
}

}  // namespace catgs::cuda::detail

// Wraps a CUDA runtime call: CATGS_CUDA(cudaMalloc(&p, bytes));
#define CATGS_CUDA(call) ::catgs::cuda::detail::check((call), #call, __FILE__, __LINE__)
// After a kernel launch: catches bad launch configurations (and sticky errors of earlier work).
#define CATGS_CUDA_LAUNCHED(kernel_name) \
  ::catgs::cuda::detail::check(cudaGetLastError(), "launch of " kernel_name, __FILE__, __LINE__)
