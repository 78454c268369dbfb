// Video encoders: one access unit out per picture in (H.264: Annex B; AV1: a temporal unit of
// low-overhead OBUs, AV1 spec section 5), from BT.709 limited-range
// I420 planes, or from a picture written straight into the encoder's own input planes
// (input_target() + encode_input(): the render core's colour conversion writes there, host
// planes for x264, CUDA device planes for NVENC with device_input: no extra copy).
//
// An Encoder is created for one frame size and used by one thread at a time (a session's encode
// job, or its one render-and-encode job with NVENC); a size change means a new Encoder.
// Implementations (libavcodec): `x264` (libx264, CPU), `nvenc` (h264_nvenc, fed host frames
// or, with the CUDA renderer, CUDA frames; see nvenc_encoder.h) and `av1` (libaom-av1's realtime
// mode, CPU; see av1_encoder.h).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "colour/yuv420.h"

namespace catgs::server {

struct EncoderConfig {
  int width = 0, height = 0;  // pixels, even, >= 16
  int fps = 60;               // nominal frame rate (time base; the VBV's frame budget)
  // Rate control (encoder_policy.h chooses these for a session). x264: capped CRF, the streaming
  // setting: `crf` is the quality floor (a still or simple view takes only the bits crf needs),
  // `bitrate_kbps` the VBV's maximum rate (a busy view is held to it, its quality drops instead),
  // `vbv_buffer_ms` the VBV's size in milliseconds of that rate (how far one frame may overshoot
  // the average: an IDR is at most about that many ms of the stream). bitrate_kbps 0: crf alone.
  // NVENC: CBR at bitrate_kbps (0: width * height * fps / 15 bits/s) with the same VBV size.
  int crf = 23;
  int bitrate_kbps = 0;
  int vbv_buffer_ms = 0;  // 0: 250 ms (x264), one frame (NVENC)
  // x264: periodic intra refresh (a column of intra blocks sweeps the picture over
  // `intra_refresh_frames` frames) instead of IDR pictures after the first one: no frame is an
  // intra-coded size spike. A forced IDR (force_idr) is still an IDR. 0: off.
  int intra_refresh_frames = 0;
  int threads = 0;  // encoder threads, 0 = the library's choice; x264 uses sliced threads (no delay)
  // x264's speed/size trade-off ("ultrafast" .. "veryslow"): streams take ultrafast, a video
  // file (catgs-render --video) a slower one for fewer bytes at the same crf. nvenc ignores it.
  std::string x264_preset = "ultrafast";
  // av1: libaom's realtime speed (cpu-used, 5..10; higher is faster and coarser). Others ignore it.
  int av1_speed = 10;
  // A container's global header: SPS/PPS once in extradata() (AV_CODEC_FLAG_GLOBAL_HEADER), not
  // in band on IDR pictures, as MP4 wants (its avcC box is made from it). Streams leave it off.
  bool global_header = false;
  // nvenc: pictures arrive as CUDA device planes (AV_PIX_FMT_CUDA frames of a hw_frames_ctx on
  // the CUDA primary context of device `cuda_device`, sw_format yuv420p; input_target() is then
  // device memory). x264 ignores both (its input is always host memory).
  bool device_input = false;
  int cuda_device = 0;  // the session's GPU (--gpus): where its renderer writes the planes
};

// One encoded access unit.
struct EncodedFrame {
  std::vector<std::uint8_t> data;  // H.264 Annex B: start codes, SPS/PPS in band on IDR frames
                                   // (unless global_header); AV1: one temporal unit, the
                                   // sequence header OBU in band on key frames
  bool key_frame = false;          // IDR (AV1: a key frame)
  double encode_ms = 0;            // encoder time (plane copy included)
  double thread_cpu_ms = 0;        // the calling thread's CPU time in the call (0 where not measured)
  // The coded picture (what a decoder shows) against the picture given, PSNR over the three
  // planes by sample count, dB, as the encoder measured it; 0 where the encoder does not (NVENC,
  // AV1). x264 only: X264Encoder.
  double psnr_db = 0;
};

class Encoder {
 public:
  virtual ~Encoder() = default;
  // "x264", "nvenc" or "av1".
  virtual std::string name() const = 0;
  // The stream's codec: "h264" or "av1".
  std::string codec() const { return name() == "av1" ? "av1" : "h264"; }
  virtual int width() const = 0;
  virtual int height() const = 0;
  // Encodes one picture given as BT.709 limited-range I420 planes of width x height (yuv420.h;
  // an RGBA8 picture converts with rgba_to_yuv420_bt709); no colour conversion happens. The
  // planes are only read during the call. The first frame, and any frame with `force_idr`, is an
  // IDR. Throws std::invalid_argument for a missing plane or a stride below the row's samples,
  // std::logic_error for an encoder fed device pictures (device_input), std::runtime_error on an
  // encoder failure.
  virtual EncodedFrame encode_yuv420(const Yuv420Planes& planes, bool force_idr) = 0;
  // The planes of the next picture (width x height I420, BT.709 limited range), to be filled
  // completely before encode_input(): host memory for x264 and host-fed NVENC, device memory of
  // a fresh hw frame for NVENC with device_input. Valid until the next encode_input() or
  // input_target() call. Throws std::runtime_error when no frame can be had.
  virtual Yuv420Target input_target() = 0;
  // Encodes the picture written into the last input_target(). IDR rules and encoder failures as
  // encode_yuv420(); throws std::logic_error without a preceding input_target().
  virtual EncodedFrame encode_input(bool force_idr) = 0;
  // The global header (EncoderConfig::global_header): H.264's SPS and PPS as Annex B NAL units
  // with start codes (AV1: the sequence header OBU), as libavcodec's extradata holds them; empty
  // without global_header.
  virtual std::vector<std::uint8_t> extradata() const = 0;
  // Sets the stream's maximum rate (EncoderConfig::bitrate_kbps) from the next picture on,
  // without an IDR. The VBV takes `vbv_buffer_ms` of the new rate (EncoderConfig's ms at the
  // nominal fps), or keeps its size in ms where that is 0. Returns false where the encoder cannot
  // (NVENC here, or an x264 stream opened without a VBV: x264 cannot add one later); the caller
  // then rebuilds it.
  virtual bool set_max_bitrate_kbps(int kbps, int vbv_buffer_ms) = 0;
};

// Creates an encoder by name:
//  "x264"  libx264;
//  "nvenc" h264_nvenc; throws std::runtime_error naming the reason when NVENC cannot be opened
//          (no NVIDIA driver, no NVENC on the GPU: H100/H200 have none, session limit);
//  "av1"   libaom-av1 (realtime);
//  "auto"  NVENC when a probe could open it, else x264. The probe (a 256x256 NVENC encoder)
//          runs once per process, on the first "auto" call; its verdict is reused.
// `why` (optional) gets a one-line reason for the choice; `fell_back` (optional) is set true when
// "auto" chose x264 because NVENC failed, false otherwise.
// Throws std::invalid_argument for an unknown name or a bad size, std::runtime_error when the
// chosen codec cannot be opened.
std::unique_ptr<Encoder> make_encoder(const std::string& kind, const EncoderConfig& config, std::string* why = nullptr,
                                      bool* fell_back = nullptr);

}  // namespace catgs::server
