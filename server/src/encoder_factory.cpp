#include <stdexcept>

#include "encoder.h"
#include "x264_encoder.h"

namespace catgs::server {

std::unique_ptr<Encoder> make_encoder(const std::string& kind, const EncoderConfig& config,
                                      std::string* why) {
  if (kind == "x264") {
    if (why) *why = "x264 requested";
    return std::make_unique<X264Encoder>(config);
  }
  if (kind == "auto") {
    // NVENC is not wired in yet; once it is, `auto` probes it first and falls back here.
    if (why) *why = "auto: x264 (NVENC support not built yet)";
    return std::make_unique<X264Encoder>(config);
  }
  throw std::invalid_argument("unknown encoder '" + kind + "' (x264 or auto)");
}

}  // namespace catgs::server
