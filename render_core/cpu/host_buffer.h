// The CPU core's host slot (issue 73): its frame buffers grow through the allocation-fault hook
// (base/allocation_faults.h), as the CUDA core's device buffers do (cuda/renderer_state.h
// GrowBuffer), so that a failed allocation is tested on both cores with the same hook.
#pragma once

#include <cstdint>
#include <new>
#include <vector>

#include "base/allocation_faults.h"

namespace catgs::cpu {

// Whether `v` needs an allocation to hold `n` elements (a growth past its capacity): only those
// growths are asked about.
template <typename T>
bool must_grow(const std::vector<T>& v, std::size_t n) {
  return n > v.capacity();
}

// Asks the hook about a growth of `bytes` for `what` and throws OutOfMemoryError where it fails,
// before anything changed.
inline void check_host_growth(std::uint64_t bytes, const char* what) {
  if (allocation_fault(bytes, what)) throw_out_of_memory("CPU renderer", what, bytes, "allocation fault injected");
}

// v.resize(n), through the hook when it must grow; a refusal (the hook, or std::bad_alloc from the
// host) throws OutOfMemoryError and leaves `v` as it was.
template <typename T>
void grow_host(std::vector<T>& v, std::size_t n, const char* what) {
  if (must_grow(v, n)) check_host_growth(static_cast<std::uint64_t>(n) * sizeof(T), what);
  try {
    v.resize(n);
  } catch (const std::bad_alloc&) {
    throw_out_of_memory("CPU renderer", what, static_cast<std::uint64_t>(n) * sizeof(T), "the host refused");
  }
}

}  // namespace catgs::cpu
