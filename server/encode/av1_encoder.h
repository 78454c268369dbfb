// AV1 through libavcodec's libaom-av1 in its realtime mode (usage realtime, no lag: one temporal
// unit out per picture in, as H.264's zerolatency), the stream a browser's WebCodecs decodes in
// software where it decodes AV1 (Chromium: dav1d). Output: one temporal unit per picture in the
// low-overhead bitstream format (AV1 spec section 5: OBUs with sizes; a temporal delimiter
// first, the sequence header OBU on every key frame), 8-bit 4:2:0, main profile, BT.709 limited
// range. Key frames on demand only (pict_type I -> AOM_EFLAG_FORCE_KF; no periodic ones).
//
// Speed: EncoderConfig::av1_speed is libaom's cpu-used (realtime: 7 slowest used here .. 10
// fastest; what each costs and buys: docs/history/encoding.md, "AV1 where the host affords it"). Threads:
// row-based multithreading and a tile per thread, columns first (up to what the width allows: a
// tile column is at least 256 pixels wide, AV1 section A.3), then rows, so threads cut one
// frame's time and add no frame of delay.
//
// Rate control, as EncoderConfig says for x264: constrained quality (libaom's end-usage cq):
// `crf` (x264's scale, 0..51) maps to libaom's cq-level on its own 0..63 scale by the same share
// of the scale, and `bitrate_kbps` with `vbv_buffer_ms` is the target rate and buffer a busy view is
// held to; bitrate_kbps 0: quality alone (end-usage q). libaom cannot change its rate in a running
// libavcodec encoder: set_max_bitrate_kbps() returns false and the session rebuilds it (a key frame).
#pragma once

#include "encode/libav_encoder.h"

namespace catgs::server {

class Av1Encoder final : public LibavEncoder {
 public:
  // Opens the codec. Throws std::invalid_argument for a bad size (odd, < 16, > 8192) or an
  // av1_speed outside [5, 10], std::runtime_error when libaom-av1 is missing or refuses the settings.
  explicit Av1Encoder(const EncoderConfig& config);
};

// libaom's cq-level (0..63) for an x264 crf (0..51): the same share of the scale, rounded.
int av1_cq_level(int x264_crf);

// log2 of the tile columns for `threads` threads on a `width`-pixel picture: at most
// log2(threads), and each column at least 256 pixels wide (AV1 section A.3: MAX_TILE_WIDTH is 4096,
// and tiles narrower than a few superblocks cost more than their threads gain).
int av1_tile_columns_log2(int width, int threads);

// log2 of the tile rows that, with 2^columns_log2 columns, give the threads a tile each: at most
// log2(threads) - columns_log2, each row at least 128 pixels (two superblocks) tall.
int av1_tile_rows_log2(int height, int threads, int columns_log2);

}  // namespace catgs::server
