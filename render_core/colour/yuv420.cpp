#include "colour/yuv420.h"

#include "colour/bt709.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace catgs {

namespace {

std::string size_text(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

}  // namespace

Yuv420Target Yuv420Image::target(int w, int h) {
  width = w;
  height = h;
  const std::size_t n = static_cast<std::size_t>(std::max(w, 0)) * static_cast<std::size_t>(std::max(h, 0));
  y.resize(n);
  u.resize(n / 4);
  v.resize(n / 4);
  return {w, h, MemoryKind::host, y.data(), w, u.data(), w / 2, v.data(), w / 2};
}

void check_yuv420_target(const char* who, const Yuv420Target& t, int width, int height) {
  const std::string w = who;
  if (width <= 0 || height <= 0 || width % 2 || height % 2)
    throw std::invalid_argument(w + ": size must be even and positive, got " + size_text(width, height));
  if (t.width != width || t.height != height)
    throw std::invalid_argument(w + ": target is " + size_text(t.width, t.height) + ", picture is " +
                                size_text(width, height));
  if (!t.y || !t.u || !t.v || t.y_stride < width || t.u_stride < width / 2 || t.v_stride < width / 2)
    throw std::invalid_argument(w + ": target needs three planes with strides >= " + std::to_string(width) + ", " +
                                std::to_string(width / 2));
}

void rgba_to_yuv420_bt709(const std::uint8_t* rgba, int width, int height, int stride_bytes, const Yuv420Target& out) {
  check_yuv420_target("rgba_to_yuv420_bt709", out, width, height);
  if (out.memory != MemoryKind::host)
    throw std::invalid_argument("rgba_to_yuv420_bt709: the CPU conversion needs a host target");
  const auto stride = static_cast<std::size_t>(stride_bytes);
  for (int r = 0; r < height; r += 2) {
    for (int c = 0; c < width; c += 2) {
      double sum[3] = {0, 0, 0};
      for (int dr = 0; dr < 2; ++dr) {
        const std::uint8_t* row = rgba + static_cast<std::size_t>(r + dr) * stride;
        std::uint8_t* y_row = out.y + static_cast<std::size_t>(r + dr) * out.y_stride;
        for (int dc = 0; dc < 2; ++dc) {
          const std::uint8_t* p = row + static_cast<std::size_t>(c + dc) * 4;
          const double R = p[0] / 255.0, G = p[1] / 255.0, B = p[2] / 255.0;
          y_row[c + dc] = bt709::luma(R, G, B);
          sum[0] += R;
          sum[1] += G;
          sum[2] += B;
        }
      }
      const double R = sum[0] / 4, G = sum[1] / 4, B = sum[2] / 4;
      out.u[static_cast<std::size_t>(r / 2) * out.u_stride + c / 2] = bt709::cb(R, G, B);
      out.v[static_cast<std::size_t>(r / 2) * out.v_stride + c / 2] = bt709::cr(R, G, B);
    }
  }
}

Yuv420Image rgba_to_yuv420_bt709(const std::uint8_t* rgba, int width, int height, int stride_bytes) {
  if (width <= 0 || height <= 0 || width % 2 || height % 2)
    throw std::invalid_argument("rgba_to_yuv420_bt709: size must be even and positive, got " +
                                size_text(width, height));
  Yuv420Image img;
  rgba_to_yuv420_bt709(rgba, width, height, stride_bytes, img.target(width, height));
  return img;
}

}  // namespace catgs
