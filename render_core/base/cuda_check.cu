// CATGS_CUDA's failure path (cuda_check.h): the message CudaError carries.
#include "base/cuda_check.h"

#include <string>

namespace catgs::cuda {

namespace detail {

void throw_cuda_error(cudaError_t err, const char* call, const char* file, int line) {
  // Clear a non-sticky error so the next call does not report it again.
  (void)cudaGetLastError();
  const char* base = file;
  for (const char* p = file; *p; ++p)
    if (*p == '/') base = p + 1;
  throw CudaError(std::string(call) + " failed at " + base + ":" + std::to_string(line) + ": " + cudaGetErrorName(err) +
                      " (" + std::to_string(static_cast<int>(err)) + "): " + cudaGetErrorString(err),
                  static_cast<int>(err));
}

}  // namespace detail

}  // namespace catgs::cuda
