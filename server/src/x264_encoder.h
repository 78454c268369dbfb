// H.264 through libavcodec's libx264: ultrafast, zerolatency, no B-frames, infinite GOP with IDR
// on demand, Annex B with SPS/PPS in band on every IDR, yuv420p BT.709 limited range.
#pragma once

#include "encoder.h"

struct AVCodecContext;
struct AVFrame;
struct AVPacket;
struct SwsContext;

namespace catgs::server {

class X264Encoder final : public Encoder {
 public:
  // Opens the codec. Throws std::invalid_argument for a bad size (odd, < 16, > 8192) and
  // std::runtime_error when libx264 is missing or refuses the settings.
  explicit X264Encoder(const EncoderConfig& config);
  ~X264Encoder() override;
  X264Encoder(const X264Encoder&) = delete;
  X264Encoder& operator=(const X264Encoder&) = delete;

  std::string name() const override { return "x264"; }
  int width() const override { return config_.width; }
  int height() const override { return config_.height; }
  EncodedFrame encode(const std::uint8_t* rgba, int stride_bytes, bool force_idr) override;

 private:
  void release();  // frees every libav object (safe on partially built encoders)

  EncoderConfig config_;
  AVCodecContext* ctx_ = nullptr;
  AVFrame* frame_ = nullptr;
  AVPacket* packet_ = nullptr;
  SwsContext* sws_ = nullptr;
  std::int64_t pts_ = 0;
};

}  // namespace catgs::server
