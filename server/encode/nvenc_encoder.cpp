#include "encode/nvenc_encoder.h"

#include <dlfcn.h>

#include <algorithm>
#include <climits>
#include <map>
#include <mutex>
#include <string>
#include <stdexcept>
#include <string>

// hwcontext_cuda.h wants cuda.h's CUcontext and CUstream; the NVENC path loads libcuda at run
// time (as h264_nvenc does) and needs no CUDA toolkit to build, so the two handle types are
// declared here (the same opaque types cuda.h declares).
#ifndef CUDA_VERSION
#define CUDA_VERSION 11000
typedef struct CUctx_st* CUcontext;
typedef struct CUstream_st* CUstream;
#endif

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/hwcontext.h>
#include <libavutil/hwcontext_cuda.h>
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

// The CUDA runtime's context on `device`: that device's primary context, where the render
// core's device pointers live (the render core renders a session on its GPU: --gpus). Retained
// once per device and process through the driver API (libcuda, loaded at run time). FFmpeg's own
// "primary_ctx" option cannot be used: it refuses a primary context that is already active with
// flags other than blocking sync, and the runtime's is active with its defaults. A context
// handed to FFmpeg as cuda_ctx is never destroyed by it.
CUcontext runtime_primary_context(int device) {
  using InitFn = int (*)(unsigned);
  using DeviceGetFn = int (*)(int*, int);
  using RetainFn = int (*)(CUcontext*, int);
  struct Driver {
    InitFn init;
    DeviceGetFn device_get;
    RetainFn retain;
  };
  static const Driver driver = [] {
    void* lib = dlopen("libcuda.so.1", RTLD_LAZY | RTLD_LOCAL);  // stays loaded
    if (!lib) throw std::runtime_error("nvenc: libcuda.so.1 cannot be loaded");
    Driver d{reinterpret_cast<InitFn>(dlsym(lib, "cuInit")), reinterpret_cast<DeviceGetFn>(dlsym(lib, "cuDeviceGet")),
             reinterpret_cast<RetainFn>(dlsym(lib, "cuDevicePrimaryCtxRetain"))};
    if (!d.init || !d.device_get || !d.retain)
      throw std::runtime_error("nvenc: libcuda.so.1 lacks cuInit/cuDeviceGet/cuDevicePrimaryCtxRetain");
    return d;
  }();
  static std::mutex mutex;
  static std::map<int, CUcontext> retained;
  const std::lock_guard<std::mutex> lock(mutex);
  if (const auto it = retained.find(device); it != retained.end()) return it->second;
  int handle = 0;
  CUcontext ctx = nullptr;
  int err = driver.init(0);
  if (err == 0) err = driver.device_get(&handle, device);
  if (err == 0) err = driver.retain(&ctx, handle);
  if (err != 0)
    throw std::runtime_error("nvenc: cannot retain the CUDA primary context of device " + std::to_string(device) +
                             " (CUresult " + std::to_string(err) + ")");
  retained[device] = ctx;
  return ctx;
}

// Device input: a CUDA device context on the runtime's context (so the render core's device
// pointers and the frames' are one address space) and a pool of yuv420p CUDA frames of the
// encoder's size, attached to `ctx` before it opens. Throws std::runtime_error on failure.
void attach_cuda_frames(AVCodecContext* ctx, const EncoderConfig& config) {
  AVBufferRef* device = av_hwdevice_ctx_alloc(AV_HWDEVICE_TYPE_CUDA);
  if (!device) throw std::runtime_error("nvenc: out of memory for the CUDA device context");
  auto* hw = reinterpret_cast<AVHWDeviceContext*>(device->data);
  try {
    reinterpret_cast<AVCUDADeviceContext*>(hw->hwctx)->cuda_ctx = runtime_primary_context(config.cuda_device);
  } catch (...) {
    av_buffer_unref(&device);
    throw;
  }
  int err = av_hwdevice_ctx_init(device);
  if (err < 0) {
    av_buffer_unref(&device);
    throw std::runtime_error("nvenc: cannot create a CUDA device context: " + av_error_text(err));
  }
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
        // One frame of VBV unless the policy says otherwise: a frame never waits behind the bits
        // of earlier ones (NVENC's default VBV is about two seconds).
        const long buffer = config.vbv_buffer_ms > 0 ? bitrate / 1000 * config.vbv_buffer_ms : bitrate / config.fps;
        ctx->rc_buffer_size = static_cast<int>(std::min<long>(buffer, INT_MAX));
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
  throw std::runtime_error(what +
                           " (the GPU may have no NVENC, e.g. H100/H200, or its "
                           "encoder sessions are all in use)");
}

}  // namespace catgs::server
