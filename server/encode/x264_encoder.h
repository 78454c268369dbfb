// H.264 from libx264 itself (x264.h; no libavcodec wrapper, so that each picture's PSNR against
// the encoder's input comes back with it: x264_picture_t.prop.f_psnr_avg, which libavcodec 5.1's
// wrapper computes but drops). EncoderConfig's preset (ultrafast for streams), tune zerolatency
// (no lookahead, no B-frames, sliced threads), an infinite GOP with IDR on demand, Annex B with
// SPS/PPS in band on every IDR (or once in extradata() with global_header), yuv420p with BT.709
// limited-range VUI. Rate control as EncoderConfig says: capped CRF (crf the quality floor, a VBV
// of bitrate_kbps and vbv_buffer_ms), optional periodic intra refresh, sliced threads.
#pragma once

#include <cstdint>
#include <vector>

#include "encode/encoder.h"

typedef struct x264_t x264_t;

namespace catgs::server {

class X264Encoder final : public Encoder {
 public:
  // Opens the encoder. Throws std::invalid_argument for a bad size (odd, < 16, > 8192) and
  // std::runtime_error when libx264 refuses the settings (an unknown preset, say).
  explicit X264Encoder(const EncoderConfig& config);
  ~X264Encoder() override;
  X264Encoder(const X264Encoder&) = delete;
  X264Encoder& operator=(const X264Encoder&) = delete;

  std::string name() const override { return "x264"; }
  int width() const override { return config_.width; }
  int height() const override { return config_.height; }
  // EncodedFrame.psnr_db: x264's PSNR of the coded picture (what a decoder shows) against the
  // picture given, over the three planes by sample count, dB.
  EncodedFrame encode_yuv420(const Yuv420Planes& planes, bool force_idr) override;
  Yuv420Target input_target() override;
  EncodedFrame encode_input(bool force_idr) override;
  std::vector<std::uint8_t> extradata() const override { return extradata_; }
  bool set_max_bitrate_kbps(int kbps, int vbv_buffer_ms) override;

 private:
  EncodedFrame encode_picture(bool force_idr);  // picture_ holds the input

  EncoderConfig config_;
  struct State;  // x264's parameters and input picture (x264.h types)
  State* state_ = nullptr;
  x264_t* encoder_ = nullptr;
  std::vector<std::uint8_t> extradata_;   // SPS and PPS (global_header)
  std::vector<std::uint8_t> header_sei_;  // x264's own SEI, put before the first access unit
  std::int64_t pts_ = 0;
  bool input_ready_ = false;  // input_target() handed out the picture and encode_input() is due
};

}  // namespace catgs::server
