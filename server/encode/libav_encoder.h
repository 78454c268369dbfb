// The part of every libavcodec H.264 encoder that does not depend on the codec: opening the
// context with BT.709 limited-range yuv420p signalling, the I420 plane path (a plane copy, no
// conversion), the in-place path (input_target(): the encoder's own frame, host or an
// AV_PIX_FMT_CUDA hw frame), IDR on demand (pict_type I), and draining one access unit per
// picture (the encoders here have no delay).
#pragma once

#include <functional>
#include <string>

#include "encode/encoder.h"

struct AVCodecContext;
struct AVFrame;
struct AVPacket;

namespace catgs::server {

class LibavEncoder : public Encoder {
 public:
  ~LibavEncoder() override;
  LibavEncoder(const LibavEncoder&) = delete;
  LibavEncoder& operator=(const LibavEncoder&) = delete;

  std::string name() const override { return name_; }
  int width() const override { return config_.width; }
  int height() const override { return config_.height; }
  EncodedFrame encode_yuv420(const Yuv420Planes& planes, bool force_idr) override;
  Yuv420Target input_target() override;
  EncodedFrame encode_input(bool force_idr) override;
  std::vector<std::uint8_t> extradata() const override;
  bool set_max_bitrate_kbps(int kbps, int vbv_buffer_ms) override;  // false: NVENC and AV1 rebuild

 protected:
  // Opens libavcodec encoder `codec_name` as `name` for config's size: sets size, yuv420p,
  // time base 1/fps, no B-frames, BT.709 limited-range colour, a global header only when
  // config.global_header (else SPS/PPS in band on every IDR), then calls `configure` for the codec's own options before
  // avcodec_open2. A `configure` that sets pix_fmt AV_PIX_FMT_CUDA and a hw_frames_ctx makes
  // the encoder take hw frames (input_target() only; encode_yuv420() then throws
  // std::logic_error). Throws std::invalid_argument for a bad size (odd, < 16, > 8192) and
  // std::runtime_error, starting with `name`, when the codec is missing or refuses to open.
  LibavEncoder(std::string name, const char* codec_name, const EncoderConfig& config,
               const std::function<void(AVCodecContext*)>& configure);

 private:
  EncodedFrame encode_frame(bool force_idr, EncodedFrame out);  // frame_ holds the picture
  void release();  // frees every libav object (safe on partially built encoders)

  std::string name_;
  EncoderConfig config_;
  AVCodecContext* ctx_ = nullptr;
  AVFrame* frame_ = nullptr;
  AVPacket* packet_ = nullptr;
  std::int64_t pts_ = 0;
  bool hw_frames_ = false;    // frame_ is an AV_PIX_FMT_CUDA frame taken from hw_frames_ctx
  bool input_ready_ = false;  // input_target() handed out frame_ and encode_input() is due
};

// Throws std::invalid_argument, starting with `name`, unless config's size is even and in
// [16, 8192] and fps is positive.
void check_encoder_config(const std::string& name, const EncoderConfig& config);

// libavcodec's text for an AVERROR code.
std::string av_error_text(int err);

}  // namespace catgs::server
