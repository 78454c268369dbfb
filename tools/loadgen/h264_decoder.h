// H.264 Annex B access units -> RGBA8 images, through libavcodec's h264 decoder (no delay:
// single thread, low-delay flag; the server's streams have no B-frames). Colour: the stream's
// BT.709 limited-range YUV 4:2:0 back to full-range RGB.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

struct AVCodecContext;
struct AVFrame;
struct AVPacket;
struct SwsContext;

namespace catgs::loadgen {

class H264Decoder {
 public:
  // Throws std::runtime_error when the decoder cannot be opened.
  H264Decoder();
  ~H264Decoder();
  H264Decoder(const H264Decoder&) = delete;
  H264Decoder& operator=(const H264Decoder&) = delete;

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
  AVCodecContext* ctx_ = nullptr;
  AVFrame* frame_ = nullptr;
  AVPacket* packet_ = nullptr;
  SwsContext* sws_ = nullptr;
  int sws_w_ = 0, sws_h_ = 0;
};

}  // namespace catgs::loadgen
