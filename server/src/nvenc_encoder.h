// H.264 through libavcodec's h264_nvenc (NVIDIA's hardware encoder) with DESIGN.md's
// low-latency settings: preset p1, tune ull, zerolatency, delay 0, no B-frames, GOP of
// INT_MAX frames (no periodic IDR; IDR on demand: pict_type I + forced-idr), CBR at
// EncoderConfig::bitrate_kbps with a one-frame VBV (rc_buffer_size = bitrate / fps), Annex B with
// SPS/PPS in band on every IDR, yuv420p BT.709 limited range signalled in the VUI.
//
// Feed (what exists): host frames. encode() converts RGBA on the CPU (swscale) and
// encode_yuv420() copies host I420 planes; libavcodec then uploads them to the GPU. The
// zero-copy path of DESIGN.md (AV_PIX_FMT_CUDA frames in a hw_frames_ctx on the render core's
// CUDA context) is NOT built: nothing here takes device pointers yet.
//
// Availability: h264_nvenc loads libcuda and libnvidia-encode at open time. On machines without
// an NVIDIA driver, and on GPUs without NVENC (H100, H200: error 2), opening fails.
#pragma once

#include "libav_encoder.h"

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
