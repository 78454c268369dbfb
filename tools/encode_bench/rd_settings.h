// catgs-encode-bench's encoder settings: one row of the rate-distortion-latency table each.
#pragma once

#include <string>
#include <vector>

#include "encode/encoder_policy.h"

namespace catgs::encode_bench {

// One row: an encoder policy (encode/encoder_policy.h) and the sessions that encode at once.
struct RdSetting {
  std::string label;  // as written, e.g. "crf=28,threads=4"
  server::EncoderPolicy policy;
  std::string encoder = "x264";  // encode/encoder.h's make_encoder kind: "x264" or "av1"
  int sessions = 1;              // concurrent encoders of this setting (each a session's own stream)
};

// Parses "k=v,k=v;k=v,..." (a ';' between rows). Keys: crf (0..51), bitrate (kbit/s, "auto" or
// "off"), bpp (auto's bits per pixel, or "auto": the content-aware rate, probed on the row's
// first frames as a server session would, encode/content_rate.h), vbv (ms), ir (intra refresh period, frames; 0 off),
// threads (0: the policy's choice for `sessions` sessions on `usable_cores`), preset ("auto": the
// policy's ladder for `sessions` sessions, or an x264 preset), sessions (>= 1), encoder (x264 or
// av1), speed (av1's libaom cpu-used, 5..10).
// Keys left out keep the server's defaults (EncoderPolicy). Throws std::invalid_argument naming
// the row and the key for anything else.
std::vector<RdSetting> parse_rd_settings(const std::string& spec, int usable_cores);

}  // namespace catgs::encode_bench
