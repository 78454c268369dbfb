#include "base/thread_clock.h"
#include "encode/x264_encoder.h"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <set>
#include <stdexcept>
#include <string>

#include "encode/encoder_policy.h"
#include "encode/libav_encoder.h"  // check_encoder_config

extern "C" {
#include <x264.h>
}

namespace catgs::server {

namespace {

constexpr int kDefaultVbvMs = 250;

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// x264's own options after the preset ("name=value:name=value"): the preset's tools turned back
// on (encoder_policy.h, parse_x264_preset), then intra refresh, whose period is the keyint.
std::string x264_params(const EncoderConfig& config) {
  std::string params = parse_x264_preset(config.x264_preset).params;
  if (config.intra_refresh_frames <= 0) return params;
  // A column of intra macroblocks crosses the picture once every intra_refresh_frames frames;
  // no IDR follows the first one.
  return params + (params.empty() ? "" : ":") + "intra-refresh=1:keyint=" + std::to_string(config.intra_refresh_frames);
}

void apply_params(x264_param_t& p, const std::string& params) {
  std::size_t at = 0;
  while (at < params.size()) {
    const std::size_t end = std::min(params.find(':', at), params.size());
    const std::string item = params.substr(at, end - at);
    const std::size_t eq = item.find('=');
    const std::string name = item.substr(0, eq), value = eq == std::string::npos ? "1" : item.substr(eq + 1);
    if (x264_param_parse(&p, name.c_str(), value.c_str()) != 0) throw std::runtime_error("x264: cannot set " + item);
    at = end + 1;
  }
}

// The VBV in x264's units (kbit/s, kbit): `vbv_ms` of the rate, at least one kbit, within an int.
void set_vbv(x264_param_t& p, int kbps, double vbv_ms) {
  p.rc.i_vbv_max_bitrate = kbps;
  p.rc.i_vbv_buffer_size = static_cast<int>(std::clamp(kbps * vbv_ms / 1000.0, 1.0, static_cast<double>(INT_MAX)));
}

// The process's threads now (Linux: /proc/self/task), to find the ones x264_encoder_open starts.
std::set<std::string> thread_ids() {
  std::set<std::string> ids;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/proc/self/task", ec)) ids.insert(e.path().filename());
  return ids;
}

// Names the sliced threads x264 started "catgs-x264" (they would carry the opening pool thread's
// name), so a host profile splits the encode from the rest of the pool's work (issue 92). A
// thread another part of the server started in the same moment (a scene's loading thread,
// another session's AV1 encoder) would be named so too: the name serves a profile only, and a
// failure only loses it.
void name_x264_threads(const std::set<std::string>& before) {
  for (const std::string& id : thread_ids())
    if (!before.count(id)) std::ofstream("/proc/self/task/" + id + "/comm") << "catgs-x264";
}

// x264's log: its errors to stderr. The rest (its banner, a warning that PSNR with psy tuning
// does not measure the tuned picture, the statistics at close) stays quiet.
void log_errors(void*, int level, const char* format, va_list args) {
  if (level > X264_LOG_ERROR) return;
  std::fputs("x264: ", stderr);
  std::vfprintf(stderr, format, args);
}

}  // namespace

struct X264Encoder::State {
  x264_param_t param;
  x264_picture_t picture;  // the input picture (x264 copies it during x264_encoder_encode)
  bool picture_allocated = false;
};

X264Encoder::X264Encoder(const EncoderConfig& config) : config_(config), state_(new State) {
  try {
    check_encoder_config("x264", config);
    const X264Preset preset = parse_x264_preset(config.x264_preset);
    x264_param_t& p = state_->param;
    // zerolatency: no lookahead, no B-frames, sliced threads, no frame of delay.
    if (x264_param_default_preset(&p, preset.preset.c_str(), "zerolatency") < 0)
      throw std::runtime_error("x264: unknown preset " + preset.preset);
    // x264 computes no PSNR below X264_LOG_INFO (x264_validate_parameters): info it is, and the
    // callback keeps only the errors.
    p.i_log_level = X264_LOG_INFO;
    p.pf_log = log_errors;
    p.i_width = config.width;
    p.i_height = config.height;
    p.i_csp = X264_CSP_I420;
    p.i_fps_num = static_cast<std::uint32_t>(config.fps);
    p.i_fps_den = 1;
    p.i_timebase_num = 1;
    p.i_timebase_den = static_cast<std::uint32_t>(config.fps);
    p.i_threads = config.threads;  // 0: X264_THREADS_AUTO
    // Sliced threads: every thread codes a band of the same picture, so threads cut a frame's
    // latency and add no delay (frame threads would pipeline frames). zerolatency picks them
    // already; stated so that no default can change it.
    p.b_sliced_threads = 1;
    p.i_keyint_max = X264_KEYINT_MAX_INFINITE;  // IDR only on demand (force_idr)
    p.i_bframe = 0;
    p.b_annexb = 1;
    // Streams: SPS/PPS in band before every IDR (a client may join at any IDR). Files: once,
    // in extradata, for the container's header.
    p.b_repeat_headers = config.global_header ? 0 : 1;
    // BT.709 limited range in the VUI (H.264 Table E-3..E-5: 1 = BT.709), so decoders
    // (WebCodecs) convert back correctly.
    p.vui.i_colorprim = 1;
    p.vui.i_transfer = 1;
    p.vui.i_colmatrix = 1;
    p.vui.b_fullrange = 0;
    // Capped CRF: quality as crf asks while the stream fits; the VBV lowers it when not.
    p.rc.i_rc_method = X264_RC_CRF;
    p.rc.f_rf_constant = static_cast<float>(config.crf);
    if (config.bitrate_kbps > 0) {
      set_vbv(p, config.bitrate_kbps, config.vbv_buffer_ms > 0 ? config.vbv_buffer_ms : kDefaultVbvMs);
      p.rc.f_vbv_buffer_init = 0.75f;  // what libavcodec's wrapper gave x264 (3/4 of the buffer)
    }
    // Each picture's PSNR against its input (x264_picture_t.prop): a sum of squared differences
    // over the reconstructed rows, which x264 filters anyway.
    p.analyse.b_psnr = 1;
    apply_params(p, x264_params(config));
    const std::set<std::string> threads_before = thread_ids();
    encoder_ = x264_encoder_open(&p);
    name_x264_threads(threads_before);
    if (!encoder_) throw std::runtime_error("x264: cannot open the encoder with preset " + config.x264_preset);
    if (x264_picture_alloc(&state_->picture, X264_CSP_I420, config.width, config.height) < 0)
      throw std::runtime_error("x264: out of memory for the input picture");
    state_->picture_allocated = true;
    if (config.global_header) {
      x264_nal_t* nal = nullptr;
      int count = 0;
      if (x264_encoder_headers(encoder_, &nal, &count) < 0) throw std::runtime_error("x264: no stream headers");
      for (int i = 0; i < count; ++i) {
        // SPS and PPS for the container; x264's SEI (its version and settings) goes in band,
        // before the first picture, where a container does not keep it.
        auto& to = nal[i].i_type == NAL_SEI ? header_sei_ : extradata_;
        to.insert(to.end(), nal[i].p_payload, nal[i].p_payload + nal[i].i_payload);
      }
    }
  } catch (...) {
    if (encoder_) x264_encoder_close(encoder_);
    if (state_->picture_allocated) x264_picture_clean(&state_->picture);
    delete state_;
    throw;
  }
}

X264Encoder::~X264Encoder() {
  x264_encoder_close(encoder_);
  x264_picture_clean(&state_->picture);
  delete state_;
}

EncodedFrame X264Encoder::encode_yuv420(const Yuv420Planes& p, bool force_idr) {
  const int w = config_.width, h = config_.height;
  if (!p.y || !p.u || !p.v || p.y_stride < w || p.u_stride < w / 2 || p.v_stride < w / 2)
    throw std::invalid_argument("x264: encode_yuv420 needs three planes with strides >= " + std::to_string(w) + ", " +
                                std::to_string(w / 2));
  const auto t0 = std::chrono::steady_clock::now();
  const double cpu0 = thread_cpu_ms();
  const Yuv420Target to = input_target();
  for (int row = 0; row < h; ++row) std::memcpy(to.y + row * to.y_stride, p.y + row * p.y_stride, w);
  for (int row = 0; row < h / 2; ++row) {
    std::memcpy(to.u + row * to.u_stride, p.u + row * p.u_stride, w / 2);
    std::memcpy(to.v + row * to.v_stride, p.v + row * p.v_stride, w / 2);
  }
  EncodedFrame out = encode_input(force_idr);
  out.encode_ms = ms_since(t0);  // the plane copy counts as encode time
  out.thread_cpu_ms = thread_cpu_ms() - cpu0;
  return out;
}

Yuv420Target X264Encoder::input_target() {
  x264_image_t& img = state_->picture.img;
  input_ready_ = true;
  return {config_.width, config_.height,  MemoryKind::host, img.plane[0],   img.i_stride[0],
          img.plane[1],  img.i_stride[1], img.plane[2],     img.i_stride[2]};
}

EncodedFrame X264Encoder::encode_input(bool force_idr) {
  if (!input_ready_) throw std::logic_error("x264: encode_input() without input_target()");
  input_ready_ = false;
  return encode_picture(force_idr);
}

EncodedFrame X264Encoder::encode_picture(bool force_idr) {
  const auto t0 = std::chrono::steady_clock::now();
  const double cpu0 = thread_cpu_ms();
  x264_picture_t& in = state_->picture;
  in.i_pts = pts_++;
  in.i_type = (force_idr || in.i_pts == 0) ? X264_TYPE_IDR : X264_TYPE_AUTO;
  x264_picture_t out_picture;
  x264_picture_init(&out_picture);
  x264_nal_t* nal = nullptr;
  int count = 0;
  const int bytes = x264_encoder_encode(encoder_, &nal, &count, &in, &out_picture);
  if (bytes < 0) throw std::runtime_error("x264: x264_encoder_encode failed");
  // Zero latency (no lookahead, no B-frames): the access unit comes out right away, its NAL
  // units back to back from nal[0].p_payload.
  if (bytes == 0 || count == 0) throw std::runtime_error("x264: no access unit for the frame");
  EncodedFrame out;
  out.data.reserve(header_sei_.size() + static_cast<std::size_t>(bytes));
  if (in.i_pts == 0) out.data = header_sei_;
  out.data.insert(out.data.end(), nal[0].p_payload, nal[0].p_payload + bytes);
  out.key_frame = out_picture.b_keyframe != 0;
  out.psnr_db = out_picture.prop.f_psnr_avg;
  out.encode_ms = ms_since(t0);
  out.thread_cpu_ms = thread_cpu_ms() - cpu0;
  return out;
}

bool X264Encoder::set_max_bitrate_kbps(int kbps, int vbv_buffer_ms) {
  // x264 changes a VBV's rate between pictures (x264_encoder_reconfig, no IDR), but cannot add a
  // VBV to a stream opened without one.
  x264_param_t& p = state_->param;
  x264_encoder_parameters(encoder_, &p);  // what the encoder runs with, as reconfig wants them
  if (kbps <= 0 || p.rc.i_vbv_max_bitrate <= 0 || p.rc.i_vbv_buffer_size <= 0) return false;
  const double vbv_ms = vbv_buffer_ms > 0 ? vbv_buffer_ms : 1000.0 * p.rc.i_vbv_buffer_size / p.rc.i_vbv_max_bitrate;
  set_vbv(p, kbps, vbv_ms);
  return x264_encoder_reconfig(encoder_, &p) == 0;
}

}  // namespace catgs::server
