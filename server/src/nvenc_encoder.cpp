#include "nvenc_encoder.h"

#include <dlfcn.h>

#include <climits>
#include <stdexcept>
#include <string>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/dict.h>
#include <libavutil/hwcontext.h>
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

// Device input: a CUDA device context on the runtime's primary context (so the render core's
// device pointers and the frames' are one address space) and a pool of yuv420p CUDA frames of
// the encoder's size, attached to `ctx` before it opens. Throws std::runtime_error on failure.
void attach_cuda_frames(AVCodecContext* ctx, const EncoderConfig& config) {
  AVDictionary* opts = nullptr;
  av_dict_set(&opts, "primary_ctx", "1", 0);
  AVBufferRef* device = nullptr;
  int err = av_hwdevice_ctx_create(&device, AV_HWDEVICE_TYPE_CUDA, "0", opts, 0);
  av_dict_free(&opts);
  if (err < 0) throw std::runtime_error("nvenc: cannot create a CUDA device context: " + av_error_text(err));
  AVBufferRef* frames = av_hwframe_ctx_alloc(device);
  av_buffer_unref(&device);  // the frames context holds its own reference
  if (!frames) throw std::runtime_error("nvenc: out of memory for the CUDA frames context");
  auto* fc = reinterpret_cast<AVHWFramesContext*>(frames->data);
  fc->format = AV_PIX_FMT_CUDA;
  fc->sw_format = AV_PIX_FMT_YUV420P;
  fc->width = config.width;
  fc->height = config.height;
  err = av_hwframe_ctx_init(frames);
  if (err < 0) {
    av_buffer_unref(&frames);
    throw std::runtime_error("nvenc: cannot create the CUDA frame pool: " + av_error_text(err));
  }
  ctx->pix_fmt = AV_PIX_FMT_CUDA;
  ctx->hw_frames_ctx = frames;  // owned by the codec context from here
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
        if (config.device_input) attach_cuda_frames(ctx, config);
      }) {
} catch (const std::runtime_error& e) {
  // The driver is there but the session did not open: say the likely cause.
  const std::string what = e.what();
  if (what.find("cannot open") == std::string::npos) throw;
  throw std::runtime_error(what + " (the GPU may have no NVENC, e.g. H100/H200, or its "
                                  "encoder sessions are all in use)");
}

}  // namespace catgs::server
