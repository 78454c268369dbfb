// H.264 through libavcodec's libx264: EncoderConfig's preset (ultrafast for streams),
// zerolatency, no B-frames, infinite GOP with IDR on demand (forced-idr), Annex B with SPS/PPS in
// band on every IDR (or once in extradata with global_header), yuv420p BT.709 limited range. Rate control as EncoderConfig says: capped CRF (crf the quality floor, a VBV of
// bitrate_kbps and vbv_buffer_ms), optional periodic intra refresh, sliced threads.
#pragma once

#include "encode/libav_encoder.h"

namespace catgs::server {

class X264Encoder final : public LibavEncoder {
 public:
  // Opens the codec. Throws std::invalid_argument for a bad size (odd, < 16, > 8192) and
  // std::runtime_error when libx264 is missing or refuses the settings.
  explicit X264Encoder(const EncoderConfig& config);
};

}  // namespace catgs::server
