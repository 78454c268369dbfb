#include "x264_encoder.h"

#include <chrono>
#include <stdexcept>
#include <string>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/error.h>
#include <libavutil/imgutils.h>
#include <libavutil/opt.h>
#include <libswscale/swscale.h>
}

namespace catgs::server {

namespace {

std::string av_error(int err) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(err, buf, sizeof(buf));
  return buf;
}

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

X264Encoder::X264Encoder(const EncoderConfig& config) : config_(config) {
  if (config.width < 16 || config.height < 16 || config.width > 8192 || config.height > 8192 ||
      config.width % 2 || config.height % 2)
    throw std::invalid_argument("x264: frame size must be even and in [16, 8192], got " +
                                std::to_string(config.width) + "x" + std::to_string(config.height));
  const AVCodec* codec = avcodec_find_encoder_by_name("libx264");
  if (!codec) throw std::runtime_error("x264: libavcodec has no libx264 encoder");
  ctx_ = avcodec_alloc_context3(codec);
  frame_ = av_frame_alloc();
  packet_ = av_packet_alloc();
  if (!ctx_ || !frame_ || !packet_) {
    release();
    throw std::runtime_error("x264: out of memory");
  }
  ctx_->width = config.width;
  ctx_->height = config.height;
  ctx_->pix_fmt = AV_PIX_FMT_YUV420P;
  ctx_->time_base = AVRational{1, config.fps};
  ctx_->framerate = AVRational{config.fps, 1};
  ctx_->max_b_frames = 0;          // B-frames add a frame of delay
  ctx_->gop_size = 1 << 30;        // X264_KEYINT_MAX_INFINITE: IDR only on demand
  ctx_->thread_count = config.threads;
  // Signal BT.709 limited range in the VUI so decoders (WebCodecs) convert back correctly.
  ctx_->colorspace = AVCOL_SPC_BT709;
  ctx_->color_range = AVCOL_RANGE_MPEG;
  ctx_->color_primaries = AVCOL_PRI_BT709;
  ctx_->color_trc = AVCOL_TRC_BT709;
  // No AV_CODEC_FLAG_GLOBAL_HEADER: x264 then repeats SPS/PPS in band before every IDR.
  av_opt_set(ctx_->priv_data, "preset", "ultrafast", 0);
  av_opt_set(ctx_->priv_data, "tune", "zerolatency", 0);
  av_opt_set_double(ctx_->priv_data, "crf", config.crf, 0);
  av_opt_set_int(ctx_->priv_data, "forced-idr", 1, 0);  // pict_type I -> IDR, not just I
  int err = avcodec_open2(ctx_, codec, nullptr);
  if (err < 0) {
    const std::string msg = "x264: cannot open encoder: " + av_error(err);
    release();
    throw std::runtime_error(msg);
  }
  frame_->format = AV_PIX_FMT_YUV420P;
  frame_->width = config.width;
  frame_->height = config.height;
  frame_->colorspace = AVCOL_SPC_BT709;
  frame_->color_range = AVCOL_RANGE_MPEG;
  err = av_frame_get_buffer(frame_, 0);
  sws_ = sws_getContext(config.width, config.height, AV_PIX_FMT_RGBA, config.width, config.height,
                        AV_PIX_FMT_YUV420P, SWS_BILINEAR, nullptr, nullptr, nullptr);
  if (err < 0 || !sws_) {
    release();
    throw std::runtime_error("x264: cannot allocate frame or colour converter");
  }
  // Full-range RGB in, BT.709 limited-range YUV out (the default would be BT.601).
  const int* bt709 = sws_getCoefficients(SWS_CS_ITU709);
  sws_setColorspaceDetails(sws_, bt709, /*srcRange=*/1, bt709, /*dstRange=*/0, 0, 1 << 16,
                           1 << 16);
}

X264Encoder::~X264Encoder() { release(); }

void X264Encoder::release() {
  if (sws_) sws_freeContext(sws_);
  sws_ = nullptr;
  av_packet_free(&packet_);
  av_frame_free(&frame_);
  avcodec_free_context(&ctx_);
}

EncodedFrame X264Encoder::encode(const std::uint8_t* rgba, int stride_bytes, bool force_idr) {
  EncodedFrame out;
  auto t0 = std::chrono::steady_clock::now();
  int err = av_frame_make_writable(frame_);
  if (err < 0) throw std::runtime_error("x264: frame not writable: " + av_error(err));
  const std::uint8_t* src[1] = {rgba};
  const int src_stride[1] = {stride_bytes};
  sws_scale(sws_, src, src_stride, 0, config_.height, frame_->data, frame_->linesize);
  out.convert_ms = ms_since(t0);

  t0 = std::chrono::steady_clock::now();
  frame_->pts = pts_++;
  frame_->pict_type = (force_idr || frame_->pts == 0) ? AV_PICTURE_TYPE_I : AV_PICTURE_TYPE_NONE;
  err = avcodec_send_frame(ctx_, frame_);
  if (err < 0) throw std::runtime_error("x264: send_frame failed: " + av_error(err));
  // zerolatency: no lookahead and no B-frames, so the access unit comes out right away.
  while ((err = avcodec_receive_packet(ctx_, packet_)) == 0) {
    out.data.insert(out.data.end(), packet_->data, packet_->data + packet_->size);
    if (packet_->flags & AV_PKT_FLAG_KEY) out.key_frame = true;
    av_packet_unref(packet_);
  }
  if (err != AVERROR(EAGAIN) && err != AVERROR_EOF)
    throw std::runtime_error("x264: receive_packet failed: " + av_error(err));
  if (out.data.empty()) throw std::runtime_error("x264: no access unit for the frame");
  out.encode_ms = ms_since(t0);
  return out;
}

}  // namespace catgs::server
