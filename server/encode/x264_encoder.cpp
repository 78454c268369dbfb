#include "encode/x264_encoder.h"

#include <cstdint>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/opt.h>
}

namespace catgs::server {

X264Encoder::X264Encoder(const EncoderConfig& config)
    : LibavEncoder("x264", "libx264", config, [&config](AVCodecContext* ctx) {
        ctx->gop_size = 1 << 30;  // X264_KEYINT_MAX_INFINITE: IDR only on demand
        av_opt_set(ctx->priv_data, "preset", "ultrafast", 0);
        av_opt_set(ctx->priv_data, "tune", "zerolatency", 0);
        av_opt_set_double(ctx->priv_data, "crf", config.crf, 0);
        av_opt_set_int(ctx->priv_data, "forced-idr", 1, 0);  // pict_type I -> IDR, not just I
        if (config.bitrate_kbps > 0) {
          // Capped CRF: quality as --crf asks while the stream fits, the VBV lowers it when not.
          // A quarter second of buffer keeps the cap tight without a frame-sized VBV's blur.
          ctx->rc_max_rate = static_cast<std::int64_t>(config.bitrate_kbps) * 1000;
          ctx->rc_buffer_size = static_cast<int>(ctx->rc_max_rate / 4);
        }
      }) {}

}  // namespace catgs::server
