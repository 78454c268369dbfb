#include "encode/x264_encoder.h"

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
      }) {}

}  // namespace catgs::server
