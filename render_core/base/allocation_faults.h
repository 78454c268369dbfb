// Allocation failures of a renderer's buffers (issue 73; docs/DESIGN.md "Device memory"): the one
// error both cores throw when a buffer cannot grow, and a process-wide hook that makes chosen
// allocations fail, so that what a failure leaves behind is tested on both cores without a GPU
// that is really full.
//
// Which allocations pass through the hook: every growth of a CUDA renderer's device buffers
// (cuda/renderer_state.h GrowBuffer, before its cudaMalloc) and every growth of the CPU core's
// frame buffers (its host slot: the pre-processed Gaussians, the render list, the image;
// cpu/host_buffer.h). Allocations that keep their size are not allocations and never fail.
#pragma once

#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>

namespace catgs {

// A renderer buffer could not grow: the device (or host slot) has no room for it. what() names
// the buffer and its bytes. The renderer that threw is whole: every buffer's recorded size is what
// it really holds, its inter-frame caches are dropped, and its next frame renders as a renderer
// that never failed would (tests/unit/allocation_faults_test.cpp, tests/gpu/allocation_faults_test.cpp).
class OutOfMemoryError : public std::runtime_error {
 public:
  OutOfMemoryError(const std::string& what, std::uint64_t bytes) : std::runtime_error(what), bytes_(bytes) {}
  std::uint64_t bytes() const { return bytes_; }  // the allocation that failed

 private:
  std::uint64_t bytes_;
};

// Asked before each allocation with its bytes and the buffer's name ("render-list keys"); true:
// that allocation fails. Called from any thread (render lanes run concurrently): it must be
// thread-safe.
using AllocationFault = std::function<bool(std::uint64_t bytes, const char* what)>;

// Installs `fault` for the whole process (an empty function: none, the default). Thread-safe.
void set_allocation_fault(AllocationFault fault);

// Whether the installed hook fails this allocation (false without one). The cores call it before
// they allocate and throw OutOfMemoryError when it says so.
bool allocation_fault(std::uint64_t bytes, const char* what);

// Throws OutOfMemoryError "<core>: <what> buffer of <bytes> bytes: <why>".
[[noreturn]] void throw_out_of_memory(const char* core, const char* what, std::uint64_t bytes, const std::string& why);

// A hook that fails each allocation with probability `probability` (0..1), drawn from a
// generator seeded with `seed` (thread-safe). For soak runs: the server installs it from the
// environment variable CATGS_FAIL_ALLOCATIONS="P[,SEED]" (allocation_fault_from_environment).
AllocationFault random_allocation_fault(double probability, std::uint64_t seed);

// Reads CATGS_FAIL_ALLOCATIONS: unset or empty: an empty function; "P" or "P,SEED" with P in
// [0, 1]: random_allocation_fault(P, SEED or 1). Throws std::invalid_argument naming the variable
// and the text for anything else.
AllocationFault allocation_fault_from_environment();

}  // namespace catgs
