// Renderer selection by name ("cpu", "cuda", "auto").
#include <cstdio>
#include <stdexcept>

#include "cpu/cpu_renderer.h"
#include "renderer/renderer.h"
#if CATGS_HAVE_CUDA
#include "cuda/cuda_renderer.h"
#endif

namespace catgs {

std::unique_ptr<Renderer> make_renderer(const std::string& kind, std::shared_ptr<const GaussianModel> model,
                                        const RenderOptions& options, std::string* why, int gpu) {
  auto say = [why](const std::string& s) {
    if (why) *why = s;
  };
  auto make_cpu = [&]() -> std::unique_ptr<Renderer> {
    if (options.pipeline == Pipeline::catgs)
      return std::make_unique<cpu::SpeculativeRenderer>(std::move(model), options);
    return std::make_unique<cpu::CpuRenderer>(std::move(model), options);
  };
  if (kind == "cpu") {
    say("cpu renderer requested");
    return make_cpu();
  }
  if (kind != "cuda" && kind != "auto")
    throw std::invalid_argument("unknown renderer '" + kind + "' (cpu, cuda or auto)");
#if CATGS_HAVE_CUDA
  std::string reason;
  if (cuda::device_usable(&reason)) {
    say("cuda renderer: " + reason);
    return cuda::make_cuda_renderer(std::move(model), options, gpu);
  }
  if (kind == "cuda") throw std::runtime_error("cuda renderer unavailable: " + reason);
  say("cpu renderer (no usable CUDA device: " + reason + ")");
#else
  if (kind == "cuda") throw std::runtime_error("cuda renderer unavailable: built without CUDA");
  say("cpu renderer (built without CUDA)");
  (void)gpu;
#endif
  return make_cpu();
}

int cuda_device_count() {
#if CATGS_HAVE_CUDA
  return cuda::device_count();
#else
  return 0;
#endif
}

bool set_cuda_host_wait(const std::string& wait) {
#if CATGS_HAVE_CUDA
  if (wait == "spin") return cuda::set_host_wait(cuda::HostWait::spin);
  if (wait == "block") return cuda::set_host_wait(cuda::HostWait::block);
  return false;
#else
  (void)wait;
  return false;
#endif
}

namespace {

// Device memory of CUDA device `gpu`, in all (`total`) or in use, or 0 without CUDA or on error.
std::size_t device_bytes(int gpu, bool total) {
#if CATGS_HAVE_CUDA
  try {
    const cuda::DeviceGuard on(gpu);
    return total ? cuda::device_memory_total() : cuda::device_memory_used();
  } catch (const std::exception&) {
    return 0;
  }
#else
  (void)gpu;
  (void)total;
  return 0;
#endif
}

}  // namespace

std::size_t cuda_device_memory_used(int gpu) { return device_bytes(gpu, false); }

std::size_t cuda_device_memory_total(int gpu) { return device_bytes(gpu, true); }

std::string cuda_upload_report(const Renderer& renderer) {
#if CATGS_HAVE_CUDA
  const auto* cuda = dynamic_cast<const cuda::CudaRenderer*>(&renderer);
  if (!cuda || !cuda->scene()) return {};
  const cuda::DeviceScene::UploadTimes& t = cuda->scene()->upload_times();
  char line[160];
  std::snprintf(line, sizeof line, "codes check %.0f ms, chunk bounds %.0f ms, copies %.0f ms (%.2f GiB at %.1f GB/s)",
                t.check_ms, t.bounds_ms, t.copy_ms, static_cast<double>(t.copied_bytes) / (1u << 30),
                t.copy_ms > 0.0 ? static_cast<double>(t.copied_bytes) / (t.copy_ms * 1e6) : 0.0);
  return line;
#else
  (void)renderer;
  return {};
#endif
}

std::uint64_t cuda_device_memory_free(int gpu) {
  const std::size_t total = device_bytes(gpu, true);
  if (total == 0) return UINT64_MAX;
  const std::size_t used = device_bytes(gpu, false);
  return used <= total ? total - used : 0;
}

}  // namespace catgs
