#include "nvenc_encoder.h"

#include <dlfcn.h>

#include <climits>
#include <stdexcept>
#include <string>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/opt.h>
}

namespace catgs::server {

long nvenc_bitrate(const EncoderConfig& config) {
  if (config.bitrate_kbps > 0) return 1000L * config.bitrate_kbps;
  return static_cast<long>(config.width) * config.height * config.fps / 15;
}

namespace {

// h264_nvenc loads these at open time; checking first turns libavcodec's terse error into a
// reason an operator can act on.
const EncoderConfig& require_nvenc_driver(const EncoderConfig& config) {
  check_encoder_config("nvenc", config);  // a bad size is the caller's error, not NVENC's
  for (const char* lib : {"libcuda.so.1", "libnvidia-encode.so.1"}) {
    void* h = dlopen(lib, RTLD_LAZY | RTLD_LOCAL);
    if (!h)
      throw std::runtime_error(std::string("nvenc: NVIDIA driver library ") + lib +
                               " cannot be loaded (no NVIDIA driver with NVENC on this machine)");
    dlclose(h);
  }
  return config;
}

}  // namespace

NvencEncoder::NvencEncoder(const EncoderConfig& config) try
    : LibavEncoder("nvenc", "h264_nvenc", require_nvenc_driver(config), [&config](AVCodecContext* ctx) {
        ctx->gop_size = INT_MAX;  // no periodic IDR (gopLength = idrPeriod = INT_MAX frames)
        const long bitrate = nvenc_bitrate(config);
        ctx->bit_rate = bitrate;
        ctx->rc_max_rate = bitrate;
        // One frame of VBV: a frame never waits behind the bits of earlier ones (NVENC's
        // default VBV is about two seconds).
        ctx->rc_buffer_size = static_cast<int>(bitrate / config.fps);
        av_opt_set(ctx->priv_data, "preset", "p1", 0);
        av_opt_set(ctx->priv_data, "tune", "ull", 0);
        av_opt_set(ctx->priv_data, "rc", "cbr", 0);
        av_opt_set_int(ctx->priv_data, "zerolatency", 1, 0);
        av_opt_set_int(ctx->priv_data, "delay", 0, 0);
        av_opt_set_int(ctx->priv_data, "forced-idr", 1, 0);  // pict_type I -> IDR
      }) {
} catch (const std::runtime_error& e) {
  // The driver is there but the session did not open: say the likely cause.
  const std::string what = e.what();
  if (what.find("cannot open") == std::string::npos) throw;
  throw std::runtime_error(what + " (the GPU may have no NVENC, e.g. H100/H200, or its "
                                  "encoder sessions are all in use)");
}

}  // namespace catgs::server
