#include "loadgen/video_decoder.h"

#include <cstring>
#include <stdexcept>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/error.h>
#include <libswscale/swscale.h>
}

namespace catgs::loadgen {

VideoDecoder::VideoDecoder(const std::string& codec_name) : codec_(codec_name) {
  if (codec_ != "h264" && codec_ != "av1")
    throw std::invalid_argument("video decoder: unknown codec '" + codec_ + "' (h264 or av1)");
  const AVCodec* codec = avcodec_find_decoder(codec_ == "av1" ? AV_CODEC_ID_AV1 : AV_CODEC_ID_H264);
  if (!codec) throw std::runtime_error(codec_ + " decoder not available");
  ctx_ = avcodec_alloc_context3(codec);
  frame_ = av_frame_alloc();
  packet_ = av_packet_alloc();
  if (!ctx_ || !frame_ || !packet_) throw std::runtime_error(codec_ + " decoder: out of memory");
  ctx_->thread_count = 1;  // frame threading would delay output by a frame per thread
  ctx_->flags |= AV_CODEC_FLAG_LOW_DELAY;
  if (avcodec_open2(ctx_, codec, nullptr) < 0) throw std::runtime_error("cannot open the " + codec_ + " decoder");
}

VideoDecoder::~VideoDecoder() {
  if (sws_) sws_freeContext(sws_);
  av_packet_free(&packet_);
  av_frame_free(&frame_);
  avcodec_free_context(&ctx_);
}

bool VideoDecoder::decode(const std::string& au, std::vector<std::uint8_t>& rgba, int& width, int& height) {
  if (av_new_packet(packet_, static_cast<int>(au.size())) < 0)
    throw std::runtime_error(codec_ + " decoder: out of memory");
  std::memcpy(packet_->data, au.data(), au.size());
  int err = avcodec_send_packet(ctx_, packet_);
  av_packet_unref(packet_);
  if (err < 0) {
    char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
    av_strerror(err, buf, sizeof(buf));
    throw std::runtime_error(codec_ + " decode: " + buf);
  }
  bool got = false;
  while (avcodec_receive_frame(ctx_, frame_) == 0) {
    width = frame_->width;
    height = frame_->height;
    if (frame_->format != AV_PIX_FMT_YUV420P) throw std::runtime_error(codec_ + " decoder: not a 4:2:0 8-bit stream");
    const std::uint8_t* planes[3] = {frame_->data[0], frame_->data[1], frame_->data[2]};
    const int strides[3] = {frame_->linesize[0], frame_->linesize[1], frame_->linesize[2]};
    to_rgba(planes, strides, width, height, rgba);
    av_frame_unref(frame_);
    got = true;
  }
  return got;
}

void VideoDecoder::to_rgba(const std::uint8_t* const planes[3], const int strides[3], int width, int height,
                           std::vector<std::uint8_t>& rgba) {
  if (!sws_ || sws_w_ != width || sws_h_ != height) {
    if (sws_) sws_freeContext(sws_);
    sws_ = sws_getContext(width, height, AV_PIX_FMT_YUV420P, width, height, AV_PIX_FMT_RGBA, SWS_BILINEAR, nullptr,
                          nullptr, nullptr);
    if (!sws_) throw std::runtime_error("video decoder: no colour converter");
    // BT.709 limited range in, full-range RGB out.
    const int* bt709 = sws_getCoefficients(SWS_CS_ITU709);
    sws_setColorspaceDetails(sws_, bt709, 0, bt709, 1, 0, 1 << 16, 1 << 16);
    sws_w_ = width;
    sws_h_ = height;
  }
  const std::size_t bytes = static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 4;
  // swscale's SIMD paths may write a little past the last row: give it slack, then trim
  // (the slack stays in the vector's capacity).
  rgba.resize(bytes + 256);
  std::uint8_t* dst[1] = {rgba.data()};
  const int dst_stride[1] = {width * 4};
  sws_scale(sws_, planes, strides, 0, height, dst, dst_stride);
  rgba.resize(bytes);
}

}  // namespace catgs::loadgen
