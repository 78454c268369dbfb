// What a session is configured with: the part of the command line (server_options.h) a
// connection's protocol state machine and its frame pipeline read, and nothing else, so a
// session depends on its own settings and not on every option of the process. It is
// ServerOptions::session: the option table (server_options.cpp) writes into it directly, so the
// member initializers below are catgs-server's defaults, shown by --help.
#pragma once

#include "encode/encoder_policy.h"
#include "proto/message_validation.h"
#include "render/lod_bound.h"
#include "session/access_tokens.h"
#include "session/rate_limit.h"

namespace catgs::server {

// The frame pipeline's settings (frame_pipeline.h).
struct FrameSettings {
  // "nvenc" | "x264" | "auto" (NVENC if it opens, else x264), as requested on the command line.
  std::string encoder = "auto";
  // How each session's stream is sized (encode/encoder_policy.h).
  EncoderPolicy encoder_policy;
  // --adaptive-quality: a session's size follows what it can keep up with (adaptive_quality.h).
  bool adaptive_quality = false;
  // --pose-prediction: frames drawn where the visitor will be when shown (pose_prediction.h).
  bool pose_prediction = true;
  // --link-control: the bitrate follows the link (link_rate.h).
  bool link_control = true;
  // --still-refine: the view a camera stops on is drawn again at full size and the stream's crf
  // (still_refine.h).
  bool still_refine = true;
  // --frame-deadline: a frame's display slot in pose intervals after its pose arrived
  // (frame_pacing.h); 0: never skip.
  double frame_deadline_slots = 2.0;
  int max_frames_in_flight = 2;         // frames queued to the transport but not yet written
  int socket_send_buffer = 512 * 1024;  // SO_SNDBUF the transport gives a socket, bytes (0: the kernel's)
  // --lod-error, --splat-budget: each frame's level-of-detail bound (render/lod_bound.h).
  LodSettings lod;
};

// A session's settings. Times are milliseconds.
struct SessionSettings {
  int max_sessions = 8;                // sessions open at once; one more gets ERROR_SERVER_FULL
  int full_retry_ms = 2000;            // ERROR_SERVER_FULL's retry_after_ms: this .. 2x this
  int hello_timeout_ms = 10000;        // no Hello this long after the WebSocket opened: ERROR_TIMEOUT
  int silent_timeout_ms = 60000;       // no message at all this long: ERROR_TIMEOUT
  int scene_load_timeout_ms = 600000;  // waiting this long for the scene to load: ERROR_TIMEOUT
  int slow_client_timeout_ms = 10000;  // frames unwritten this long: ERROR_TOO_SLOW
  int max_viewport_width = 3840;       // a larger Hello/Resize: ERROR_INVALID_ARGUMENT
  int max_viewport_height = 2160;      //   (pixel count and longer side; message_validation.h)
  RateLimitSettings rate_limits;       // --rate-limits (rate_limit.h)
  AccessTokens tokens;                 // Hello.token must be one of them when there is one
  ExportLimits export_limits;          // caps on ExportVideoRequest (message_validation.h)
  FrameSettings frame;
};

}  // namespace catgs::server
