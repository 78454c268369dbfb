#include "encode/content_rate.h"

#include <algorithm>

#include "encode/x264_encoder.h"

namespace catgs::server {

double content_bits_per_pixel(double crf_bits_per_pixel) {
  return std::clamp(crf_bits_per_pixel * kContentHeadroom, kContentMinBitsPerPixel, kContentMaxBitsPerPixel);
}

ContentRateProbe::ContentRateProbe(const EncoderPolicy& policy, int width, int height, int threads,
                                   const std::string& preset)
    : width_(width), height_(height) {
  EncoderConfig c;
  c.width = width;
  c.height = height;
  c.crf = policy.crf;
  c.bitrate_kbps = 0;  // crf alone: what this content wants at the quality floor
  c.threads = threads;
  c.x264_preset = preset;
  encoder_ = std::make_unique<X264Encoder>(c);
}

void ContentRateProbe::add(const Yuv420Planes& planes) {
  if (done()) return;
  const EncodedFrame e = encoder_->encode_yuv420(planes, false);
  if (fed_++ == 0) return;  // the IDR
  bits_ += 8.0 * static_cast<double>(e.data.size());
  ++counted_;
}

double ContentRateProbe::crf_bits_per_pixel() const {
  if (counted_ == 0) return 0;
  return bits_ / counted_ / (static_cast<double>(width_) * height_);
}

double ContentRates::bits_per_pixel(int width, int height) const {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = rates_.find({width, height});
  return it == rates_.end() ? 0 : it->second;
}

bool ContentRates::claim(int width, int height) {
  std::lock_guard<std::mutex> lock(mutex_);
  return rates_.emplace(std::make_pair(width, height), 0.0).second;
}

void ContentRates::release(int width, int height) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = rates_.find({width, height});
  if (it != rates_.end() && it->second == 0) rates_.erase(it);
}

void ContentRates::set(int width, int height, double bits_per_pixel) {
  std::lock_guard<std::mutex> lock(mutex_);
  rates_[{width, height}] = bits_per_pixel;
}

}  // namespace catgs::server
