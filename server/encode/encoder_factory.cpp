#include <mutex>
#include <stdexcept>

#include "encode/av1_encoder.h"
#include "encode/encoder.h"
#include "encode/nvenc_encoder.h"
#include "encode/x264_encoder.h"

namespace catgs::server {

namespace {

// The verdict of the once-per-process NVENC probe.
struct NvencProbe {
  bool ok = false;
  std::string reason;  // why NVENC cannot be used (empty when ok)
};

const NvencProbe& nvenc_probe() {
  static const NvencProbe probe = [] {
    NvencProbe p;
    try {
      EncoderConfig c;
      c.width = c.height = 256;
      NvencEncoder e(c);
      p.ok = true;
    } catch (const std::exception& ex) {
      p.reason = ex.what();
    }
    return p;
  }();  // thread-safe static initialisation: one probe even with concurrent first calls
  return probe;
}

}  // namespace

std::unique_ptr<Encoder> make_encoder(const std::string& kind, const EncoderConfig& config, std::string* why,
                                      bool* fell_back) {
  if (fell_back) *fell_back = false;
  if (kind == "x264") {
    if (why) *why = "x264 requested";
    return std::make_unique<X264Encoder>(config);
  }
  if (kind == "nvenc") {
    if (why) *why = "nvenc requested";
    return std::make_unique<NvencEncoder>(config);
  }
  if (kind == "av1") {
    if (why) *why = "av1 requested";
    return std::make_unique<Av1Encoder>(config);
  }
  if (kind == "auto") {
    const NvencProbe& probe = nvenc_probe();
    if (probe.ok) {
      try {
        auto e = std::make_unique<NvencEncoder>(config);
        if (why) *why = "auto: NVENC available";
        return e;
      } catch (const std::runtime_error& ex) {
        // The probe opened, this one did not (e.g. the GPU's session limit): x264 for this one.
        if (why) *why = std::string("auto: x264 (") + ex.what() + ")";
      }
    } else if (why) {
      *why = "auto: x264 (" + probe.reason + ")";
    }
    if (fell_back) *fell_back = true;
    return std::make_unique<X264Encoder>(config);
  }
  throw std::invalid_argument("unknown encoder '" + kind + "' (nvenc, x264, av1 or auto)");
}

}  // namespace catgs::server
