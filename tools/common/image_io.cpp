// PNG I/O (stb, Debian's libstb) and image comparison.
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include <stb_image.h>
#include <stb_image_write.h>

#include "colour/bt709.h"
#include "common/image_io.h"

namespace catgs {

double psnr_rgba8(const Image& a, const Image& b) {
  if (a.width != b.width || a.height != b.height || a.rgba8.size() != b.rgba8.size())
    throw std::invalid_argument("psnr: image sizes differ");
  double se = 0.0;
  const std::size_t pixels = a.rgba8.size() / 4;
  for (std::size_t p = 0; p < pixels; ++p)
    for (int c = 0; c < 3; ++c) {
      const double d = double(a.rgba8[4 * p + c]) - double(b.rgba8[4 * p + c]);
      se += d * d;
    }
  if (se == 0.0) return std::numeric_limits<double>::infinity();
  const double mse = se / (3.0 * static_cast<double>(pixels));
  return 10.0 * std::log10(255.0 * 255.0 / mse);
}

namespace {

// BT.709 luma of every pixel of an 8-bit RGBA image, full range (0..255).
std::vector<double> luma709(const Image& im) {
  std::vector<double> y(static_cast<std::size_t>(im.width) * static_cast<std::size_t>(im.height));
  for (std::size_t p = 0; p < y.size(); ++p)
    y[p] = bt709::kKr * im.rgba8[4 * p] + bt709::kKg * im.rgba8[4 * p + 1] + bt709::kKb * im.rgba8[4 * p + 2];
  return y;
}

}  // namespace

double ssim_luma_rgba8(const Image& a, const Image& b) {
  if (a.width != b.width || a.height != b.height || a.rgba8.size() != b.rgba8.size())
    throw std::invalid_argument("ssim: image sizes differ");
  constexpr int kWin = 8, kStep = 4;
  if (a.width < kWin || a.height < kWin) throw std::invalid_argument("ssim: images smaller than 8x8");
  constexpr double c1 = (0.01 * 255) * (0.01 * 255), c2 = (0.03 * 255) * (0.03 * 255);
  const std::vector<double> x = luma709(a), y = luma709(b);
  double sum = 0;
  long windows = 0;
  for (int y0 = 0; y0 + kWin <= a.height; y0 += kStep)
    for (int x0 = 0; x0 + kWin <= a.width; x0 += kStep) {
      double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
      for (int j = 0; j < kWin; ++j)
        for (int i = 0; i < kWin; ++i) {
          const std::size_t p = static_cast<std::size_t>(y0 + j) * static_cast<std::size_t>(a.width) + (x0 + i);
          sx += x[p];
          sy += y[p];
          sxx += x[p] * x[p];
          syy += y[p] * y[p];
          sxy += x[p] * y[p];
        }
      constexpr double n = kWin * kWin;
      const double mx = sx / n, my = sy / n;
      const double vx = sxx / n - mx * mx, vy = syy / n - my * my, cov = sxy / n - mx * my;
      sum += (2 * mx * my + c1) * (2 * cov + c2) / ((mx * mx + my * my + c1) * (vx + vy + c2));
      ++windows;
    }
  return sum / static_cast<double>(windows);
}

Image box_downsample(const Image& hi, int factor) {
  if (factor < 1 || hi.width % factor != 0 || hi.height % factor != 0)
    throw std::invalid_argument("box_downsample: size " + std::to_string(hi.width) + "x" + std::to_string(hi.height) +
                                " is not a multiple of factor " + std::to_string(factor));
  if (hi.rgb.size() != static_cast<std::size_t>(hi.width) * hi.height * 3)
    throw std::invalid_argument("box_downsample: the image has no float colours");
  Image lo;
  lo.width = hi.width / factor;
  lo.height = hi.height / factor;
  lo.rgb.assign(static_cast<std::size_t>(lo.width) * lo.height * 3, 0.0f);
  lo.rgba8.assign(static_cast<std::size_t>(lo.width) * lo.height * 4, 255);
  const float inv = 1.0f / (static_cast<float>(factor) * static_cast<float>(factor));  // no int overflow
  for (int y = 0; y < lo.height; ++y)
    for (int x = 0; x < lo.width; ++x) {
      const std::size_t o = static_cast<std::size_t>(y) * lo.width + x;
      for (int c = 0; c < 3; ++c) {
        float sum = 0.0f;
        for (int dy = 0; dy < factor; ++dy)
          for (int dx = 0; dx < factor; ++dx) {
            const std::size_t i = static_cast<std::size_t>(y * factor + dy) * hi.width + (x * factor + dx);
            sum += std::clamp(hi.rgb[3 * i + c], 0.0f, 1.0f);  // NaN stays NaN: to_unorm8 maps it to 0
          }
        lo.rgb[3 * o + c] = sum * inv;
        lo.rgba8[4 * o + c] = to_unorm8(lo.rgb[3 * o + c]);
      }
    }
  return lo;
}

void write_png(const Image& image, const std::string& path) {
  if (image.rgba8.size() != static_cast<std::size_t>(image.width) * image.height * 4)
    throw std::runtime_error(path + ": image has no 8-bit pixels to write");
  std::vector<uint8_t> rgb(static_cast<std::size_t>(image.width) * image.height * 3);
  for (std::size_t p = 0; p < rgb.size() / 3; ++p)
    for (int c = 0; c < 3; ++c) rgb[3 * p + c] = image.rgba8[4 * p + c];
  if (!stbi_write_png(path.c_str(), image.width, image.height, 3, rgb.data(), image.width * 3))
    throw std::runtime_error(path + ": cannot write PNG");
}

Image read_png(const std::string& path) {
  int w = 0, h = 0, channels = 0;
  uint8_t* data = stbi_load(path.c_str(), &w, &h, &channels, 4);
  if (!data) throw std::runtime_error(path + ": cannot read image: " + stbi_failure_reason());
  Image img;
  img.width = w;
  img.height = h;
  img.rgba8.assign(data, data + static_cast<std::size_t>(w) * h * 4);
  stbi_image_free(data);
  return img;
}

}  // namespace catgs
