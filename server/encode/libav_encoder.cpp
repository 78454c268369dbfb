#include "encode/libav_encoder.h"

#include <chrono>
#include <stdexcept>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/error.h>
#include <libavutil/hwcontext.h>
#include <libavutil/imgutils.h>
}

namespace catgs::server {

namespace {

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

std::string av_error_text(int err) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(err, buf, sizeof(buf));
  return buf;
}

void check_encoder_config(const std::string& name, const EncoderConfig& config) {
  if (config.width < 16 || config.height < 16 || config.width > 8192 || config.height > 8192 || config.width % 2 ||
      config.height % 2)
    throw std::invalid_argument(name + ": frame size must be even and in [16, 8192], got " +
                                std::to_string(config.width) + "x" + std::to_string(config.height));
  if (config.fps <= 0) throw std::invalid_argument(name + ": fps must be positive");
}

LibavEncoder::LibavEncoder(std::string name, const char* codec_name, const EncoderConfig& config,
                           const std::function<void(AVCodecContext*)>& configure)
    : name_(std::move(name)), config_(config) {
  check_encoder_config(name_, config);
  const AVCodec* codec = avcodec_find_encoder_by_name(codec_name);
  if (!codec) throw std::runtime_error(name_ + ": libavcodec has no " + codec_name + " encoder");
  ctx_ = avcodec_alloc_context3(codec);
  frame_ = av_frame_alloc();
  packet_ = av_packet_alloc();
  if (!ctx_ || !frame_ || !packet_) {
    release();
    throw std::runtime_error(name_ + ": out of memory");
  }
  ctx_->width = config.width;
  ctx_->height = config.height;
  ctx_->pix_fmt = AV_PIX_FMT_YUV420P;
  ctx_->time_base = AVRational{1, config.fps};
  ctx_->framerate = AVRational{config.fps, 1};
  ctx_->max_b_frames = 0;  // B-frames add a frame of delay
  ctx_->thread_count = config.threads;
  // Signal BT.709 limited range in the VUI so decoders (WebCodecs) convert back correctly.
  ctx_->colorspace = AVCOL_SPC_BT709;
  ctx_->color_range = AVCOL_RANGE_MPEG;
  ctx_->color_primaries = AVCOL_PRI_BT709;
  ctx_->color_trc = AVCOL_TRC_BT709;
  // Streams: no AV_CODEC_FLAG_GLOBAL_HEADER, so SPS/PPS come in band before every IDR (a client
  // may join at any IDR). Files: SPS/PPS once, in extradata, for the container's header.
  if (config.global_header) ctx_->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
  try {
    configure(ctx_);
  } catch (...) {
    release();
    throw;
  }
  hw_frames_ = ctx_->pix_fmt == AV_PIX_FMT_CUDA;
  int err = avcodec_open2(ctx_, codec, nullptr);
  if (err < 0) {
    const std::string msg = name_ + ": cannot open " + codec_name + ": " + av_error_text(err);
    release();
    throw std::runtime_error(msg);
  }
  if (hw_frames_) return;  // frames come from the hw_frames_ctx pool, one per picture
  frame_->format = AV_PIX_FMT_YUV420P;
  frame_->width = config.width;
  frame_->height = config.height;
  frame_->colorspace = AVCOL_SPC_BT709;
  frame_->color_range = AVCOL_RANGE_MPEG;
  err = av_frame_get_buffer(frame_, 0);
  if (err < 0) {
    release();
    throw std::runtime_error(name_ + ": cannot allocate a frame: " + av_error_text(err));
  }
}

LibavEncoder::~LibavEncoder() { release(); }

void LibavEncoder::release() {
  av_packet_free(&packet_);
  av_frame_free(&frame_);
  avcodec_free_context(&ctx_);
}

EncodedFrame LibavEncoder::encode_yuv420(const Yuv420Planes& p, bool force_idr) {
  if (!p.y || !p.u || !p.v || p.y_stride < config_.width || p.u_stride < config_.width / 2 ||
      p.v_stride < config_.width / 2)
    throw std::invalid_argument(name_ + ": encode_yuv420 needs three planes with strides >= " +
                                std::to_string(config_.width) + ", " + std::to_string(config_.width / 2));
  if (hw_frames_) throw std::logic_error(name_ + ": takes device pictures (input_target()) only");
  input_ready_ = false;  // frame_ is overwritten here
  const auto t0 = std::chrono::steady_clock::now();
  const int err = av_frame_make_writable(frame_);
  if (err < 0) throw std::runtime_error(name_ + ": frame not writable: " + av_error_text(err));
  const int w = config_.width, h = config_.height;
  av_image_copy_plane(frame_->data[0], frame_->linesize[0], p.y, p.y_stride, w, h);
  av_image_copy_plane(frame_->data[1], frame_->linesize[1], p.u, p.u_stride, w / 2, h / 2);
  av_image_copy_plane(frame_->data[2], frame_->linesize[2], p.v, p.v_stride, w / 2, h / 2);
  EncodedFrame out = encode_frame(force_idr, EncodedFrame{});
  out.encode_ms = ms_since(t0);  // the plane copy counts as encode time
  return out;
}

Yuv420Target LibavEncoder::input_target() {
  int err = 0;
  if (hw_frames_) {
    // A fresh pool frame each picture: the encoder may still hold the previous one.
    av_frame_unref(frame_);
    err = av_hwframe_get_buffer(ctx_->hw_frames_ctx, frame_, 0);
    if (err < 0) throw std::runtime_error(name_ + ": no hw frame: " + av_error_text(err));
    frame_->colorspace = AVCOL_SPC_BT709;
    frame_->color_range = AVCOL_RANGE_MPEG;
  } else {
    err = av_frame_make_writable(frame_);
    if (err < 0) throw std::runtime_error(name_ + ": frame not writable: " + av_error_text(err));
  }
  input_ready_ = true;
  return {config_.width,       config_.height,      hw_frames_ ? MemoryKind::device : MemoryKind::host,
          frame_->data[0],     frame_->linesize[0], frame_->data[1],
          frame_->linesize[1], frame_->data[2],     frame_->linesize[2]};
}

EncodedFrame LibavEncoder::encode_input(bool force_idr) {
  if (!input_ready_) throw std::logic_error(name_ + ": encode_input() without input_target()");
  input_ready_ = false;
  return encode_frame(force_idr, EncodedFrame{});
}

std::vector<std::uint8_t> LibavEncoder::extradata() const {
  if (!ctx_->extradata || ctx_->extradata_size <= 0) return {};
  return {ctx_->extradata, ctx_->extradata + ctx_->extradata_size};
}

bool LibavEncoder::set_max_bitrate_kbps(int, int) {
  // NVENC and libaom through libavcodec take a new rate only by a rebuild (x264, which takes it
  // between pictures, is X264Encoder): the caller rebuilds.
  return false;
}

EncodedFrame LibavEncoder::encode_frame(bool force_idr, EncodedFrame out) {
  const auto t0 = std::chrono::steady_clock::now();
  frame_->pts = pts_++;
  frame_->pict_type = (force_idr || frame_->pts == 0) ? AV_PICTURE_TYPE_I : AV_PICTURE_TYPE_NONE;
  frame_->key_frame = frame_->pict_type == AV_PICTURE_TYPE_I;
  int err = avcodec_send_frame(ctx_, frame_);
  if (err < 0) throw std::runtime_error(name_ + ": send_frame failed: " + av_error_text(err));
  // Zero latency (no lookahead, no B-frames): the access unit comes out right away.
  while ((err = avcodec_receive_packet(ctx_, packet_)) == 0) {
    out.data.insert(out.data.end(), packet_->data, packet_->data + packet_->size);
    if (packet_->flags & AV_PKT_FLAG_KEY) out.key_frame = true;
    av_packet_unref(packet_);
  }
  if (err != AVERROR(EAGAIN) && err != AVERROR_EOF)
    throw std::runtime_error(name_ + ": receive_packet failed: " + av_error_text(err));
  if (out.data.empty()) throw std::runtime_error(name_ + ": no access unit for the frame");
  out.encode_ms = ms_since(t0);
  return out;
}

}  // namespace catgs::server
