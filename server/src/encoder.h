// Video encoders: RGBA8 host images in, one H.264 Annex B access unit out per frame.
//
// An Encoder is created for one frame size and used by one thread at a time (a session's render
// job); a size change means a new Encoder. Implementations: x264 (libavcodec libx264, CPU);
// nvenc comes later behind the same interface.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace catgs::server {

struct EncoderConfig {
  int width = 0, height = 0;  // pixels, even, >= 16
  int fps = 60;               // nominal rate (time base / rate-control hint only)
  int crf = 23;               // x264 constant rate factor
  int threads = 0;            // encoder threads, 0 = the library's choice
};

// One encoded access unit.
struct EncodedFrame {
  std::vector<std::uint8_t> data;  // H.264 Annex B: start codes, SPS/PPS in band on IDR frames
  bool key_frame = false;          // IDR
  double convert_ms = 0;           // RGBA -> YUV 4:2:0 time
  double encode_ms = 0;            // encoder time
};

class Encoder {
 public:
  virtual ~Encoder() = default;
  // "x264", "nvenc", ...
  virtual std::string name() const = 0;
  virtual int width() const = 0;
  virtual int height() const = 0;
  // Encodes one RGBA8 image (width x height, row-major, top row first, `stride_bytes` per row;
  // colour treated as full-range sRGB/BT.709 primaries). The first frame, and any frame with
  // `force_idr`, is an IDR. Output is signalled as BT.709 limited-range yuv420p. Throws
  // std::runtime_error on an encoder failure.
  virtual EncodedFrame encode(const std::uint8_t* rgba, int stride_bytes, bool force_idr) = 0;
};

// Creates an encoder by name: "x264" or "auto" (x264 for now; `why` gets a one-line reason).
// Throws std::invalid_argument for an unknown name or bad size, std::runtime_error when the
// codec cannot be opened.
std::unique_ptr<Encoder> make_encoder(const std::string& kind, const EncoderConfig& config,
                                      std::string* why = nullptr);

}  // namespace catgs::server
