// Renderer's default colour-converted render: host frame, CPU conversion (yuv420.h).
#include <chrono>
#include <stdexcept>

#include "renderer/renderer.h"

namespace catgs {

double Renderer::render_yuv420_at(const Camera& camera, double time_s, const Yuv420Target& out) {
  check_yuv420_target("render_yuv420_at", out, camera.width, camera.height);
  if (out.memory != MemoryKind::host)
    throw std::invalid_argument("render_yuv420_at: the " + name() + " renderer cannot write a device target");
  render_at(camera, time_s, yuv_source_);
  const auto t0 = std::chrono::steady_clock::now();
  rgba_to_yuv420_bt709(yuv_source_.rgba8.data(), yuv_source_.width, yuv_source_.height, yuv_source_.width * 4, out);
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace catgs
