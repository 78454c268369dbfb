// Sessions spread over the server's GPUs (--gpus; issue 21 item 5): each session renders on one
// GPU for its whole life (its renderer's buffers and the scene copy it reads live there), chosen
// when its renderer is made as the GPU with the fewest sessions (the lowest index on a tie).
// Sessions differ in cost, but a session's cost is not known when it starts, and balancing counts
// keeps every GPU's share of the stream within one session of the others. Thread-safe.
#pragma once

#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

namespace catgs::server {

// "all" -> 0 .. visible - 1; "0,2" -> those devices (each below `visible`, no repeats). Throws
// std::invalid_argument naming the problem (an empty list, a device that is not visible, a
// repeat, not a number) or when `visible` is 0.
std::vector<int> parse_gpus(const std::string& spec, int visible);

class GpuAssignment {
 public:
  // `devices`: the CUDA devices to use, in order; empty: no GPUs (the CPU renderer), where
  // acquire() answers -1.
  explicit GpuAssignment(std::vector<int> devices);

  // The device of the GPU with the fewest sessions (counted from now on), or -1 without GPUs.
  int acquire();
  // A session on `device` ended (a device acquire() did not answer is ignored).
  void release(int device);
  // Sessions on each device, in the order of devices().
  std::vector<std::int64_t> sessions() const;
  const std::vector<int>& devices() const { return devices_; }

 private:
  std::vector<int> devices_;
  mutable std::mutex mutex_;
  std::vector<std::int64_t> sessions_;
};

}  // namespace catgs::server
