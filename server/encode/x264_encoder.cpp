#include "encode/x264_encoder.h"

#include "encode/encoder_policy.h"

#include <algorithm>
#include <climits>
#include <cstdint>
#include <string>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/opt.h>
}

namespace catgs::server {

namespace {

constexpr int kDefaultVbvMs = 250;

// x264's own options, given as x264-params (libavcodec has no field for intra refresh's period).
// The preset's tools turned back on (encoder_policy.h, parse_x264_preset) come first.
std::string x264_params(const EncoderConfig& config) {
  std::string params = parse_x264_preset(config.x264_preset).params;
  if (config.intra_refresh_frames <= 0) return params;
  // keyint is the refresh period under intra refresh: a column of intra macroblocks crosses
  // the picture once every intra_refresh_frames frames; no IDR follows the first one.
  return params + (params.empty() ? "" : ":") + "intra-refresh=1:keyint=" + std::to_string(config.intra_refresh_frames);
}

}  // namespace

X264Encoder::X264Encoder(const EncoderConfig& config)
    : LibavEncoder("x264", "libx264", config, [&config](AVCodecContext* ctx) {
        ctx->gop_size = 1 << 30;  // X264_KEYINT_MAX_INFINITE: IDR only on demand
        // Sliced threads: every thread codes a band of the same picture, so threads cut a
        // frame's latency and add no frame of delay (frame threads would pipeline frames).
        // zerolatency picks them already; stated here so that no default can change it.
        ctx->thread_type = FF_THREAD_SLICE;
        av_opt_set(ctx->priv_data, "preset", parse_x264_preset(config.x264_preset).preset.c_str(), 0);
        av_opt_set(ctx->priv_data, "tune", "zerolatency", 0);
        av_opt_set_double(ctx->priv_data, "crf", config.crf, 0);
        av_opt_set_int(ctx->priv_data, "forced-idr", 1, 0);  // pict_type I -> IDR, not just I
        if (config.bitrate_kbps > 0) {
          // Capped CRF: quality as crf asks while the stream fits, the VBV lowers it when not.
          ctx->rc_max_rate = static_cast<std::int64_t>(config.bitrate_kbps) * 1000;
          const int vbv_ms = config.vbv_buffer_ms > 0 ? config.vbv_buffer_ms : kDefaultVbvMs;
          // --bitrate and --vbv-ms are bounded, their product is not within an int: clamped.
          ctx->rc_buffer_size = static_cast<int>(std::min<std::int64_t>(ctx->rc_max_rate * vbv_ms / 1000, INT_MAX));
        }
        const std::string params = x264_params(config);
        if (!params.empty()) av_opt_set(ctx->priv_data, "x264-params", params.c_str(), 0);
      }) {}

}  // namespace catgs::server
