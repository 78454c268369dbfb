#include "yuv420.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace catgs::server {

namespace {

// BT.709 luma weights and the chroma scale factors 2 (1 - Kb), 2 (1 - Kr).
constexpr double kKr = 0.2126, kKb = 0.0722, kKg = 1.0 - kKr - kKb;
constexpr double kCbScale = 2.0 * (1.0 - kKb), kCrScale = 2.0 * (1.0 - kKr);

std::uint8_t to_byte(double x) {
  return static_cast<std::uint8_t>(std::clamp(std::lround(x), 0L, 255L));
}

}  // namespace

Yuv420Image rgba_to_yuv420_bt709(const std::uint8_t* rgba, int width, int height,
                                 int stride_bytes) {
  if (width <= 0 || height <= 0 || width % 2 || height % 2)
    throw std::invalid_argument("rgba_to_yuv420_bt709: size must be even and positive, got " +
                                std::to_string(width) + "x" + std::to_string(height));
  Yuv420Image out;
  out.width = width;
  out.height = height;
  const std::size_t w = static_cast<std::size_t>(width), h = static_cast<std::size_t>(height);
  out.y.resize(w * h);
  out.u.resize(w * h / 4);
  out.v.resize(w * h / 4);
  for (std::size_t r = 0; r < h; r += 2) {
    for (std::size_t c = 0; c < w; c += 2) {
      double sum[3] = {0, 0, 0};
      for (std::size_t dr = 0; dr < 2; ++dr) {
        const std::uint8_t* row = rgba + (r + dr) * static_cast<std::size_t>(stride_bytes);
        for (std::size_t dc = 0; dc < 2; ++dc) {
          const std::uint8_t* p = row + (c + dc) * 4;
          const double R = p[0] / 255.0, G = p[1] / 255.0, B = p[2] / 255.0;
          out.y[(r + dr) * w + c + dc] = to_byte(16.0 + 219.0 * (kKr * R + kKg * G + kKb * B));
          sum[0] += R;
          sum[1] += G;
          sum[2] += B;
        }
      }
      const double R = sum[0] / 4, G = sum[1] / 4, B = sum[2] / 4;
      const double Y = kKr * R + kKg * G + kKb * B;
      const std::size_t k = (r / 2) * (w / 2) + c / 2;
      out.u[k] = to_byte(128.0 + 224.0 * (B - Y) / kCbScale);
      out.v[k] = to_byte(128.0 + 224.0 * (R - Y) / kCrScale);
    }
  }
  return out;
}

}  // namespace catgs::server
