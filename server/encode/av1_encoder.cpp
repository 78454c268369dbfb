#include "encode/av1_encoder.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/opt.h>
}

namespace catgs::server {

namespace {

constexpr int kDefaultVbvMs = 250;

// libavcodec's libaom wrapper caps cpu-used at 8; libaom's realtime mode takes up to 10, so the
// speed goes to libaom itself through aom-params.
std::string aom_params(const EncoderConfig& config) { return "cpu-used=" + std::to_string(config.av1_speed); }

}  // namespace

int av1_cq_level(int x264_crf) { return std::clamp(static_cast<int>(std::lround(x264_crf * 63.0 / 51.0)), 0, 63); }

int av1_tile_columns_log2(int width, int threads) {
  int log2 = 0;
  while ((2 << log2) <= threads && (width >> (log2 + 1)) >= 256 && log2 < 6) ++log2;
  return log2;
}

int av1_tile_rows_log2(int height, int threads, int columns_log2) {
  int log2 = 0;
  while ((2 << (columns_log2 + log2)) <= threads && (height >> (log2 + 1)) >= 128 && log2 < 6) ++log2;
  return log2;
}

Av1Encoder::Av1Encoder(const EncoderConfig& config)
    : LibavEncoder("av1", "libaom-av1", config, [&config](AVCodecContext* ctx) {
        if (config.av1_speed < 5 || config.av1_speed > 10)
          throw std::invalid_argument("av1: speed (libaom cpu-used) must be in [5, 10], got " +
                                      std::to_string(config.av1_speed));
        ctx->gop_size = INT_MAX;  // key frames only on demand
        ctx->keyint_min = INT_MAX;
        ctx->profile = FF_PROFILE_AV1_MAIN;
        av_opt_set(ctx->priv_data, "usage", "realtime", 0);
        av_opt_set_int(ctx->priv_data, "lag-in-frames", 0, 0);  // no look-ahead: no frame of delay
        av_opt_set_int(ctx->priv_data, "row-mt", 1, 0);
        const int columns = av1_tile_columns_log2(config.width, config.threads);
        av_opt_set_int(ctx->priv_data, "tile-columns", columns, 0);
        av_opt_set_int(ctx->priv_data, "tile-rows", av1_tile_rows_log2(config.height, config.threads, columns), 0);
        av_opt_set_int(ctx->priv_data, "crf", av1_cq_level(config.crf), 0);
        if (config.bitrate_kbps > 0) {
          ctx->bit_rate = static_cast<std::int64_t>(config.bitrate_kbps) * 1000;
          ctx->rc_max_rate = ctx->bit_rate;
          const int vbv_ms = config.vbv_buffer_ms > 0 ? config.vbv_buffer_ms : kDefaultVbvMs;
          ctx->rc_buffer_size = static_cast<int>(std::min<std::int64_t>(ctx->bit_rate * vbv_ms / 1000, INT_MAX));
        }
        av_opt_set(ctx->priv_data, "aom-params", aom_params(config).c_str(), 0);
      }) {}

}  // namespace catgs::server
