// The calling thread's CPU time: what a step costs the host's cores, its waits left out (issue 92:
// where a session's cores go, split by step without a profiler).
#pragma once

#include <ctime>

namespace catgs {

// CLOCK_THREAD_CPUTIME_ID in milliseconds; differences of two readings on one thread are the CPU
// it spent between them.
inline double thread_cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

}  // namespace catgs
