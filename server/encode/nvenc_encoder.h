// H.264 through libavcodec's h264_nvenc (NVIDIA's hardware encoder) with the low-latency settings
// of docs/DESIGN.md "Encoder policy": preset p1, tune ull, zerolatency, delay 0, no B-frames, GOP
// of INT_MAX frames (no periodic IDR; IDR on demand: pict_type I + forced-idr), CBR at
// EncoderConfig::bitrate_kbps with a VBV of vbv_buffer_ms (one frame when 0), Annex B with
// SPS/PPS in band on every IDR, yuv420p BT.709 limited range signalled in the VUI.
//
// Feed: with EncoderConfig::device_input, zero copy: the encoder opens with pix_fmt
// AV_PIX_FMT_CUDA and a hw_frames_ctx (sw_format yuv420p) on a CUDA device context that uses
// the primary context of EncoderConfig::cuda_device (the session's GPU), the one the CUDA runtime
// (and so the render core) uses there
// (retained through the driver API and handed to FFmpeg as its cuda_ctx);
// input_target() hands out a pool frame's device planes, which the render core's colour
// conversion writes (CudaRenderer::render_yuv420_at), and nothing crosses to the host. Without
// it, host frames: encode_yuv420() and input_target() take host I420 planes, and libavcodec
// uploads them.
//
// Availability: h264_nvenc loads libcuda and libnvidia-encode at open time. On machines without
// an NVIDIA driver, and on GPUs without NVENC (H100, H200: error 2), opening fails.
#pragma once

#include "encode/libav_encoder.h"

namespace catgs::server {

class NvencEncoder final : public LibavEncoder {
 public:
  // Opens an NVENC session. Throws std::invalid_argument for a bad size and
  // std::runtime_error starting with "nvenc:" and naming libavcodec's error when NVENC cannot be
  // opened (no driver, no NVENC on this GPU, too many sessions).
  explicit NvencEncoder(const EncoderConfig& config);
};

// The CBR target NVENC uses for `config`, bits per second (bitrate_kbps, or the default of
// width * height * fps / 15).
long nvenc_bitrate(const EncoderConfig& config);

}  // namespace catgs::server
