// The encoder policy: how a session's H.264 stream is sized for the network and for the host,
// instead of two fixed numbers (issue 35). Every default here comes from the rate-distortion-
// latency table that catgs-encode-bench measured (RESULTS.md, "Encoder policy").
//
// Rate: a target bitrate by resolution and rate, target = bits_per_pixel x width x height x fps
// (at least min_kbps: a small picture needs more bits a pixel for the same look), used as the
// VBV's maximum rate of a capped CRF stream (crf the quality floor; EncoderConfig). A client's
// Quality.max_bitrate_kbps lowers it further, never raises it.
//
// Threads: x264's sliced threads cut one frame's encode time, so a lone session should get
// several; but the host's cores are shared by every session's encoder, so the threads a session
// gets are 2 x usable cores / live sessions (an encoder is busy only part of each frame
// interval, and more threads cost little more CPU a frame), at least what its viewport needs to
// keep 60 frames/s (needed_threads) and at most what it gains from (useful_threads). When
// sessions join, a session's next encoder gets fewer threads; when they leave, more (the server
// rebuilds an encoder only when its thread count should change, see should_rebuild()).
#pragma once

#include <chrono>

#include "encode/encoder.h"

namespace catgs::server {

struct EncoderPolicy {
  // --bitrate: < 0 (auto) target from bits_per_pixel; 0 (off) crf alone; > 0 that many kbit/s.
  int bitrate_kbps = -1;
  double bits_per_pixel = 0.09;  // --bits-per-pixel: auto's bits per pixel per frame
  int min_kbps = 1500;           // auto's floor (small viewports)
  int crf = 23;                  // --crf: the quality floor
  int vbv_buffer_ms = 100;       // --vbv-ms: the VBV's size in ms of the target rate
  int intra_refresh_frames = 0;  // --intra-refresh N: refresh period in frames (0: off)
  int threads = 0;               // --encoder-threads: > 0 fixed per session; 0 auto (above)
  int usable_cores = 1;          // the cores this process may use (cpu_quota.h)
};

// The VBV maximum rate in kbit/s for a width x height stream at `fps` frames/s; `client_max_kbps`
// (Quality.max_bitrate_kbps, 0: none) caps it. 0 means crf alone (policy.bitrate_kbps == 0 and
// no client cap).
int target_bitrate_kbps(const EncoderPolicy& policy, int width, int height, int fps, int client_max_kbps);

// The most sliced threads a width x height picture gains from (the measured table in
// RESULTS.md: beyond it a frame's encode time no longer falls).
int useful_threads(int width, int height);

// The fewest sliced threads that encode a width x height frame within 3/4 of a 60 Hz frame
// interval (the measured table in RESULTS.md): fewer and the session cannot hold 60 frames/s.
int needed_threads(int width, int height);

// x264 threads for one session's encoder while `live_sessions` sessions share the host.
int encoder_threads(const EncoderPolicy& policy, int width, int height, int live_sessions);

// The whole EncoderConfig for a session's encoder (size, fps, rate control, threads).
EncoderConfig encoder_config(const EncoderPolicy& policy, int width, int height, int fps, int live_sessions,
                             int client_max_kbps);

// Whether a running encoder with `current_threads` should be rebuilt for `wanted` threads. Fewer
// threads take effect at once (sessions joined: the cores are oversubscribed now); more only
// after `since_last_build` >= kGrowDelay (sessions left: no IDR storm while a tour group comes
// and goes). A rebuild costs an IDR.
constexpr std::chrono::seconds kGrowDelay{5};
bool should_rebuild(int current_threads, int wanted, std::chrono::steady_clock::duration since_last_build);

}  // namespace catgs::server
