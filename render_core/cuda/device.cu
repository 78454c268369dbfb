// Device queries for the CUDA core (cuda_renderer.h): usable device, description, memory.
#include <atomic>
#include <cstdio>
#include <string>

#include "base/cuda_check.h"
#include "cuda/cuda_renderer.h"

namespace catgs::cuda {

namespace {
// Probe: does this binary hold code the device can run (sm_90 SASS or compute_90 PTX)?
__global__ void probe_kernel() {}
}  // namespace

bool device_usable(std::string* reason) {
  auto say = [reason](const std::string& s) {
    if (reason) *reason = s;
  };
  int count = 0;
  cudaError_t err = cudaGetDeviceCount(&count);
  if (err != cudaSuccess) {
    (void)cudaGetLastError();
    say(std::string("cudaGetDeviceCount: ") + cudaGetErrorString(err));
    return false;
  }
  if (count == 0) {
    say("no CUDA device");
    return false;
  }
  int device = 0;
  cudaDeviceProp prop{};
  if ((err = cudaGetDevice(&device)) != cudaSuccess || (err = cudaGetDeviceProperties(&prop, device)) != cudaSuccess) {
    (void)cudaGetLastError();
    say(std::string("device query: ") + cudaGetErrorString(err));
    return false;
  }
  cudaFuncAttributes attr{};
  err = cudaFuncGetAttributes(&attr, probe_kernel);
  const std::string who =
      std::string(prop.name) + " (sm_" + std::to_string(prop.major) + std::to_string(prop.minor) + ")";
  if (err != cudaSuccess) {
    (void)cudaGetLastError();
    say(who + ": this build has no code for it: " + cudaGetErrorString(err));
    return false;
  }
  say(who);
  return true;
}

std::string device_description() {
  int device = 0;
  cudaDeviceProp prop{};
  CATGS_CUDA(cudaGetDevice(&device));
  CATGS_CUDA(cudaGetDeviceProperties(&prop, device));
  char buf[256];
  std::snprintf(buf, sizeof buf, "%s, sm_%d%d, %d SMs, %.1f GiB, L2 %.0f MiB", prop.name, prop.major, prop.minor,
                prop.multiProcessorCount, static_cast<double>(prop.totalGlobalMem) / (1024.0 * 1024.0 * 1024.0),
                static_cast<double>(prop.l2CacheSize) / (1024.0 * 1024.0));
  return buf;
}

int device_count() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    (void)cudaGetLastError();
    return 0;
  }
  return count;
}

namespace {
std::atomic<HostWait> g_host_wait{HostWait::spin};
}  // namespace

HostWait host_wait() { return g_host_wait.load(std::memory_order_relaxed); }

unsigned host_wait_event_flags() {
  return cudaEventDisableTiming | (host_wait() == HostWait::block ? cudaEventBlockingSync : 0u);
}

bool set_host_wait(HostWait wait) {
  g_host_wait.store(wait, std::memory_order_relaxed);
  const unsigned flags = wait == HostWait::block ? cudaDeviceScheduleBlockingSync : cudaDeviceScheduleAuto;
  int previous = 0;
  if (cudaGetDevice(&previous) != cudaSuccess) {
    (void)cudaGetLastError();
    return false;
  }
  bool ok = true;
  for (int d = 0; d < device_count(); ++d) {
    const bool set = cudaSetDevice(d) == cudaSuccess && cudaSetDeviceFlags(flags) == cudaSuccess;
    if (!set) (void)cudaGetLastError();
    ok = ok && set;
  }
  if (cudaSetDevice(previous) != cudaSuccess) (void)cudaGetLastError();
  return ok;
}

DeviceGuard::DeviceGuard(int device) {
  CATGS_CUDA(cudaGetDevice(&previous_));
  if (device != previous_) {
    CATGS_CUDA(cudaSetDevice(device));
    changed_ = true;
  }
}

DeviceGuard::~DeviceGuard() {
  if (changed_) (void)cudaSetDevice(previous_);  // destructors must not throw
}

std::size_t device_memory_used() {
  std::size_t free_bytes = 0, total = 0;
  CATGS_CUDA(cudaMemGetInfo(&free_bytes, &total));
  return total - free_bytes;
}

std::size_t device_memory_total() {
  std::size_t free_bytes = 0, total = 0;
  CATGS_CUDA(cudaMemGetInfo(&free_bytes, &total));
  return total;
}

}  // namespace catgs::cuda
