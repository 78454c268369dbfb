// The server's video access units -> RGBA8 images, through libavcodec: H.264 Annex B access units
// (its h264 decoder) or AV1 temporal units of low-overhead OBUs (its AV1 decoder: libdav1d where
// libavcodec has it). No delay: one thread, the low-delay flag; the server's streams have no
// B-frames and no reordering. Colour: the stream's BT.709 limited-range YUV 4:2:0 back to
// full-range RGB.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

struct AVCodecContext;
struct AVFrame;
struct AVPacket;
struct SwsContext;

namespace catgs::loadgen {

class VideoDecoder {
 public:
  // `codec`: "h264" or "av1" (the names of encode/encoder.h's codecs). Throws
  // std::invalid_argument for another name, std::runtime_error when libavcodec has no decoder
  // for it or it cannot be opened.
  explicit VideoDecoder(const std::string& codec = "h264");
  ~VideoDecoder();
  VideoDecoder(const VideoDecoder&) = delete;
  VideoDecoder& operator=(const VideoDecoder&) = delete;

  const std::string& codec() const { return codec_; }
  // Decodes one access unit. Returns true with `rgba` (width*height*4, row-major, top row
  // first) filled when a picture came out; false when the decoder produced none (e.g. P-frames
  // before the first IDR). Throws std::runtime_error for corrupt data.
  bool decode(const std::string& access_unit, std::vector<std::uint8_t>& rgba, int& width, int& height);
  // The colour conversion decode() applies to a decoded picture, on any BT.709 limited-range
  // I420 planes (Y, U, V with their strides): what a stream would show with no coding loss, the
  // ceiling of a stream's PSNR against the RGB it was made from (4:2:0 chroma, 8-bit rounding).
  void to_rgba(const std::uint8_t* const planes[3], const int strides[3], int width, int height,
               std::vector<std::uint8_t>& rgba);

 private:
  std::string codec_;
  AVCodecContext* ctx_ = nullptr;
  AVFrame* frame_ = nullptr;
  AVPacket* packet_ = nullptr;
  SwsContext* sws_ = nullptr;
  int sws_w_ = 0, sws_h_ = 0;
};

}  // namespace catgs::loadgen
