// Sessions spread over the server's GPUs (--gpus; issue 21 item 5) and held to their memory
// (issue 61): each session renders on one GPU for its whole life (its renderer's buffers and the
// scene copy it reads live there), chosen when its renderer is made as the GPU with the fewest
// sessions among those whose memory can hold its buffers (the lowest index on a tie). Sessions
// differ in cost, but a session's cost is not known when it starts, and balancing counts keeps
// every GPU's share of the stream within one session of the others.
//
// Memory (docs/DESIGN.md "Device memory"): each GPU has a capacity (its memory less a reserve for
// the CUDA context and the encoders, or --device-memory-mb), holds its scene copies (add_scene) and
// the sessions' reservations (renderer/device_memory.h's estimate, raised to what a session's
// buffers really grew to: update). A session is placed only where its reservation fits; where none
// fits, place() says why and the server refuses the visitor at the door (ERROR_SERVER_FULL)
// instead of ending a running session when an allocation fails. The CPU renderer has one slot,
// the host (device -1), whose capacity is the --device-memory-mb allowance (0: unlimited), so the
// same accounting runs and is tested without a GPU. Thread-safe.
//
// What is free (issue 73): the accounting counts only the server's own scenes and sessions, and a
// GPU may be shared (another server pod, a training job, a driver that holds more than it says).
// With a `free_memory` probe (cudaMemGetInfo on a GPU), a slot's room for a new session is the
// lesser of the accounting's and the driver's: what it reports free, less `free_reserve`, less what
// the slot's sessions may still grow into (their reservations less what their buffers hold,
// hold()). Placement reads the probe at the door; the refusal's reason and /readyz say which binds.
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <memory>
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
  // One GPU's (or the host's) memory, bytes.
  struct Memory {
    int device = -1;
    std::int64_t sessions = 0;
    std::uint64_t capacity = 0;  // 0: unlimited
    std::uint64_t scenes = 0;    // scene copies
    std::uint64_t reserved = 0;  // sessions' reservations
    std::uint64_t held = 0;      // what the sessions' buffers hold now (hold())
    // The driver's free bytes at the last probe (UINT64_MAX: no probe).
    std::uint64_t driver_free = UINT64_MAX;
    // What another session may still reserve by the accounting (UINT64_MAX when unlimited).
    std::uint64_t room() const;
    // By the driver: driver_free less `free_reserve` and the sessions' growth still to come
    // (reserved - held); UINT64_MAX without a probe.
    std::uint64_t driver_room(std::uint64_t free_reserve) const;
  };
  // Bytes the driver reports free on `device` now (UINT64_MAX: unknown). Never throws.
  using FreeMemory = std::function<std::uint64_t(int device)>;
  struct Placement {
    int device = -1;  // the GPU (-1: the host, CPU renderer)
    bool placed = false;
    std::string why;  // when not placed: what each GPU has and the session needs
    // Not placed, though the accounting alone had room on some GPU: the driver's free memory bound.
    bool driver_binds = false;
  };

  // `devices`: the CUDA devices to use, in order; empty: no GPUs (the CPU renderer: one host
  // slot, device -1). `capacity`: bytes per device in that order (missing or 0: unlimited);
  // with no devices, capacity[0] is the host's allowance.
  // `free_memory`: the driver's probe (empty: the accounting alone), `free_reserve`: bytes kept
  // back from what it reports (the CUDA context's growth, the encoders).
  explicit GpuAssignment(std::vector<int> devices, std::vector<std::uint64_t> capacity = {},
                         FreeMemory free_memory = {}, std::uint64_t free_reserve = 0);

  // Places a session that needs `bytes`: the GPU with the fewest sessions among those with room
  // (the lesser of the accounting's and the driver's; the lowest index on a tie), reserving them
  // there. Not placed: nothing changes, and `why` says, for each GPU, what it has and which of the
  // two binds.
  Placement place(std::uint64_t bytes);
  // place(0).device: the device of the GPU with the fewest sessions, or -1 without GPUs.
  int acquire() { return place(0).device; }
  // A session on `device` that reserved `bytes` and held `held` ended (a device place() did not
  // answer is ignored).
  void release(int device, std::uint64_t bytes = 0, std::uint64_t held = 0);
  // What a session's buffers on `device` hold changes from `from` to `to` bytes.
  void hold(int device, std::uint64_t from, std::uint64_t to);
  // A session's reservation on `device` changes from `from` to `to` bytes (its buffers grew, or
  // its viewport changed). Applied even past the capacity (the buffers are already there);
  // returns whether the device is still within it.
  bool update(int device, std::uint64_t from, std::uint64_t to);
  // A scene copy of `bytes` on `device` (-1: the host slot of the CPU renderer) until the
  // returned hold is dropped.
  std::shared_ptr<void> add_scene(int device, std::uint64_t bytes);

  // Sessions on each device, in the order of devices().
  std::vector<std::int64_t> sessions() const;
  // Every slot's memory: the GPUs in the order of devices(), or the host slot.
  std::vector<Memory> memory() const;
  // The most any one slot may still reserve (UINT64_MAX when one is unlimited), the driver read
  // now; `why`, when given: which of the two binds on that slot ("accounting" or "driver").
  std::uint64_t largest_room(std::string* binds = nullptr) const;
  const std::vector<int>& devices() const { return devices_; }

 private:
  int slot_of(int device) const;  // -1: not ours
  void probe_locked() const;      // reads the driver into every slot's driver_free
  std::uint64_t room_locked(const Memory& m) const { return std::min(m.room(), m.driver_room(free_reserve_)); }

  std::vector<int> devices_;
  FreeMemory free_memory_;
  std::uint64_t free_reserve_ = 0;
  mutable std::mutex mutex_;
  mutable std::vector<Memory> slots_;  // driver_free: refreshed by const readers
};

// "12.3 GiB" / "512 MiB": for refusal reasons and logs.
std::string memory_text(std::uint64_t bytes);

}  // namespace catgs::server
