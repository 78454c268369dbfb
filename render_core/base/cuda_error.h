// The error every CUDA call of ours throws when it fails (base/cuda_check.h CATGS_CUDA), without
// the CUDA headers, so code that only catches it (the server, the tools) needs no CUDA toolkit.
#pragma once

#include <stdexcept>
#include <string>

namespace catgs::cuda {

// A failed CUDA call: what() = "<call> failed at <file>:<line>: <cudaErrorName> (<code>): <text>".
class CudaError : public std::runtime_error {
 public:
  CudaError(const std::string& what, int code) : std::runtime_error(what), code_(code) {}
  int code() const { return code_; }  // the cudaError_t value

 private:
  int code_;
};

}  // namespace catgs::cuda
