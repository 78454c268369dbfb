#include "encode/encoder_policy.h"

#include <algorithm>
#include <cmath>

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
  // Sliced threads split the picture into bands of macroblock rows; below a few rows a band's
  // fixed cost (its own slice header, prediction stopping at its edges) outweighs the split.
  const long pixels = static_cast<long>(width) * height;
  if (pixels <= 640L * 360) return 2;
  if (pixels <= 1280L * 720) return 4;
  if (pixels <= 1920L * 1080) return 8;
  return 12;
}

int encoder_threads(const EncoderPolicy& policy, int width, int height, int live_sessions) {
  if (policy.threads > 0) return policy.threads;
  const int share = std::max(1, policy.usable_cores / std::max(1, live_sessions));
  return std::max(1, std::min(useful_threads(width, height), share));
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
  return c;
}

bool should_rebuild(int current_threads, int wanted, std::chrono::steady_clock::duration since_last_build) {
  if (wanted < current_threads) return true;
  return wanted > current_threads && since_last_build >= kGrowDelay;
}

}  // namespace catgs::server
