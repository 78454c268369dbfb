#include "encode/encoder_policy.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace catgs::server {

int target_bitrate_kbps(const EncoderPolicy& policy, int width, int height, int fps, int client_max_kbps) {
  int kbps = policy.bitrate_kbps;
  if (kbps < 0) {
    const double bits = policy.bits_per_pixel * width * height * std::max(fps, 1);
    kbps = std::max(policy.min_kbps, static_cast<int>(std::lround(bits / 1000.0)));
  }
  if (client_max_kbps > 0) kbps = kbps == 0 ? client_max_kbps : std::min(kbps, client_max_kbps);
  return kbps;
}

int useful_threads(int width, int height) {
  // Sliced threads split the picture into bands of macroblock rows; past some count a band's
  // fixed cost (its slice header, prediction stopping at its edges, waking its thread) outweighs
  // the split. The counts are where catgs-encode-bench's encode time stopped falling for one
  // session alone on the H100 host (docs/history/encoding.md, "Encoder policy": 8 at 720p and 1080p, where 12
  // was worse at p95); 640x360 and sizes past 1080p were not measured and take a neighbour's.
  const long pixels = static_cast<long>(width) * height;
  if (pixels <= 640L * 360) return 4;
  if (pixels <= 1920L * 1080) return 8;
  return 12;
}

int needed_threads(int width, int height) {
  // A thread per 1.5 M pixels: the rule that matches catgs-encode-bench's table on the H100 host
  // (docs/history/encoding.md, "Encoder policy": 720p within 12.5 ms at p95, 3/4 of a 60 Hz frame interval, on
  // one thread; 1080p on two, not on one). Past 1080p it is an extrapolation.
  const double pixels = static_cast<double>(width) * height;
  return std::clamp(static_cast<int>(std::ceil(pixels / 1.5e6)), 1, useful_threads(width, height));
}

int encoder_threads(const EncoderPolicy& policy, int width, int height, int live_sessions) {
  if (policy.threads > 0) return policy.threads;
  // A session's encoder is busy only part of each frame interval, and sliced threads cost about
  // the same CPU a frame as one thread (docs/history/encoding.md, "Encoder policy"), so the cores are shared at
  // twice their count: the threads wait less for each other than the sessions do.
  const int share = std::max(1, 2 * policy.usable_cores / std::max(1, live_sessions));
  return std::clamp(share, needed_threads(width, height), useful_threads(width, height));
}

double ultrafast_cpu_ms(int width, int height) { return 7.7e-6 * static_cast<double>(width) * height; }

namespace {

// Whether ladder step k's CPU time, for `live_sessions` streams, fits the encoders' share.
bool step_fits(const EncoderPolicy& policy, int k, int width, int height, int fps, int live_sessions) {
  // CPU ms a second the encoders may use, and what the sessions' frames cost at ultrafast.
  const double budget_ms = kEncoderCpuShare * std::max(1, policy.usable_cores) * 1000.0;
  const double sessions_ms = ultrafast_cpu_ms(width, height) * std::max(fps, 1) * std::max(1, live_sessions);
  return sessions_ms * kPresetLadder[k].cpu_factor <= budget_ms;
}

}  // namespace

int preset_step(const EncoderPolicy& policy, int width, int height, int fps, int live_sessions) {
  int step = 0;
  for (int k = 1; k < kPresetSteps; ++k)
    if (step_fits(policy, k, width, height, fps, live_sessions)) step = k;
  return std::max(step, policy.floor_step);
}

bool cores_hold(const EncoderPolicy& policy, int width, int height, int fps, int live_sessions) {
  if (policy.floor_step < 0 || policy.x264_preset != "auto") return true;
  return step_fits(policy, policy.floor_step, width, height, fps, live_sessions);
}

int ladder_step_named(const std::string& name) {
  if (name == "off") return -1;
  for (int k = 0; k < kPresetSteps; ++k)
    if (name == kPresetLadder[k].name) return k;
  throw std::invalid_argument("'" + name +
                              "' is off or a step of the x264 ladder (ultrafast, ultrafast+cabac+deblock, superfast)");
}

bool use_av1(const EncoderPolicy& policy, int width, int height, int fps, int live_sessions, bool client_decodes_av1,
             bool cpu_encoder, bool link_limited) {
  if (!client_decodes_av1 || !cpu_encoder || link_limited || policy.av1 == "off") return false;
  if (policy.av1 == "on") return true;
  const double budget_ms = kEncoderCpuShare * std::max(1, policy.usable_cores) * 1000.0;
  const double per_session_ms = ultrafast_cpu_ms(width, height) * std::max(fps, 1) * std::max(1, live_sessions);
  const double interval_ms = 1000.0 / std::max(fps, 1);
  return per_session_ms * kAv1CpuFactor <= budget_ms &&
         av1_frame_ms(width, height, encoder_threads(policy, width, height, live_sessions)) <=
             kAv1FrameIntervalShare * interval_ms;
}

double av1_frame_ms(int width, int height, int threads) {
  const double t = std::clamp(threads, 1, 8);
  const double speedup = 1.0 + (kAv1EightThreadSpeedup - 1.0) * (t - 1.0) / 7.0;
  return ultrafast_cpu_ms(width, height) * kAv1CpuFactor / speedup;
}

std::string encoder_preset(const EncoderPolicy& policy, int width, int height, int fps, int live_sessions) {
  if (policy.x264_preset != "auto") return policy.x264_preset;
  return kPresetLadder[preset_step(policy, width, height, fps, live_sessions)].name;
}

X264Preset parse_x264_preset(const std::string& name) {
  X264Preset out;
  std::size_t at = name.find('+');
  out.preset = name.substr(0, at);
  bool known = false;
  for (const char* p :
       {"ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow", "placebo"})
    known = known || out.preset == p;
  if (!known) throw std::invalid_argument("not an x264 preset: '" + name + "'");
  bool cabac = false, deblock = false;
  while (at != std::string::npos) {
    const std::size_t next = name.find('+', at + 1);
    const std::string tool = name.substr(at + 1, next == std::string::npos ? std::string::npos : next - at - 1);
    bool& on = tool == "cabac" ? cabac : deblock;
    if ((tool != "cabac" && tool != "deblock") || on)
      throw std::invalid_argument("x264 preset '" + name + "': '+" + tool + "' is not cabac or deblock, once each");
    on = true;
    at = next;
  }
  if (cabac) out.params = "cabac=1";
  if (deblock) out.params += std::string(out.params.empty() ? "" : ":") + "deblock=1";
  return out;
}

bool is_x264_preset(const std::string& name) {
  try {
    parse_x264_preset(name);
    return true;
  } catch (const std::invalid_argument&) {
    return false;
  }
}

EncoderConfig encoder_config(const EncoderPolicy& policy, int width, int height, int fps, int live_sessions,
                             int client_max_kbps) {
  EncoderConfig c;
  c.width = width;
  c.height = height;
  c.fps = fps;
  c.crf = policy.crf;
  c.bitrate_kbps = target_bitrate_kbps(policy, width, height, fps, client_max_kbps);
  c.vbv_buffer_ms = policy.vbv_buffer_ms;
  c.intra_refresh_frames = policy.intra_refresh_frames;
  c.threads = encoder_threads(policy, width, height, live_sessions);
  c.x264_preset = encoder_preset(policy, width, height, fps, live_sessions);
  c.av1_speed = policy.av1_speed;
  return c;
}

bool should_rebuild(int current_threads, int wanted, std::chrono::steady_clock::duration since_last_build) {
  if (wanted < current_threads) return true;
  return wanted > current_threads && since_last_build >= kGrowDelay;
}

}  // namespace catgs::server
