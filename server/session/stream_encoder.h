// The encode side of a session's frames (issue 93: FramePipeline split by concern; the render
// side is frame_pipeline.h): the session's encoder through its life, brought each frame to the
// settings the encoder policy decides for it in one call (encode/frame_encoding.h) by a new VBV
// rate where x264 takes one or else a rebuild, and the scene's content-rate probe at the
// stream's size (encode/content_rate.h, --bits-per-pixel auto).
//
// Threading: open() on the session's strand before any job; stream_is_av1() on the strand; the
// rest in the one job that encodes (the worker pool's encode job, or the one-job path's render
// lane), never two at a time.
#pragma once

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "encode/content_rate.h"
#include "encode/encoder.h"
#include "encode/frame_encoding.h"
#include "proto/message_validation.h"
#include "process/server_metrics.h"
#include "session/session_settings.h"

namespace catgs::server {

// What a frame is asked for, as the session decided it (SessionStream::admit), from its render job
// to its encode.
struct JobShape {
  int width = 0, height = 0;                             // pixels, after adaptive quality's scaling
  int quality_level = 0;                                 // AdaptiveQuality level the size was scaled to
  int max_bitrate_kbps = 0;                              // Quality.max_bitrate_kbps (0: the server's default)
  LinkInputs link;                                       // the link's state (link_rate.h; read again at the encode)
  std::chrono::steady_clock::time_point link_read_at{};  // when `link` was read (at the encode)
  double previous_send_ms = 0;                           // FrameTimings.previous_send_ms
  int fps = kStreamFps;                                  // the client's display rate (Pose.display_hz)
};

class StreamEncoder {
 public:
  // `settings` and `metrics` outlive it (the server holds them).
  StreamEncoder(const FrameSettings& settings, ServerMetrics& metrics) : settings_(settings), metrics_(metrics) {}
  // Gives back a content-rate probe's claim that did not end.
  ~StreamEncoder();
  StreamEncoder(const StreamEncoder&) = delete;
  StreamEncoder& operator=(const StreamEncoder&) = delete;

  // At Welcome: whether the stream may be AV1 (`av1_ok`: the client decodes it and the server's
  // encoders are x264's CPU ones), the scene's probed rate caps (`content_rates`, the
  // LoadedScene's; null: the policy's bits a pixel alone), the CUDA device frames come from (-1:
  // none) and whether they come as device frames (the one-job path: NVENC takes the CUDA frame);
  // `scene_name` for the probe's log line.
  void open(bool av1_ok, std::shared_ptr<ContentRates> content_rates, int gpu, bool device_input,
            std::string scene_name);

  // Whether a stream of `shape` at `live_sessions` sessions would be AV1 now (the encoder
  // policy's use_av1): Welcome.codec before the first frame.
  bool stream_is_av1(const JobShape& shape, int live_sessions) const;

  // Decides the frame's encoder settings (frame_encoding) and brings the encoder to them: a new
  // VBV rate where x264 takes one, else a rebuild (sets `idr`). `refine`: the still view's refine
  // frame (its cap lifted for this frame where x264 can). Returns the settings.
  FrameEncoding prepare(const JobShape& shape, bool refine, bool& idr);
  // The encoder prepare() brought to the frame's settings.
  Encoder& encoder() { return *encoder_; }

  // --bits-per-pixel auto: feeds an encoded frame's planes to this session's probe of the scene
  // at the frame's size, when it holds the size's claim (or takes it) and the camera (`pose`)
  // moved; stores the result once the probe is done.
  void probe_content_rate(const JobShape& shape, const CameraPose& pose, const FrameEncoding& settings,
                          const Yuv420Planes& planes);

  // Stats.encoder for its frames: "x264 " + preset, "nvenc", "av1".
  const std::string& label() const { return label_; }
  // Whether its frames are encoded under a VBV rate (the policy's, a client's or the link's cap).
  bool rate_capped() const { return rate_kbps_ > 0; }
  // Whether the frame just prepared is a refine frame that lifted a VBV cap (x264 kept the
  // buffer's fill from the capped frames: still_refine.h); reading it clears it.
  bool take_refine_lifted_cap() { return std::exchange(refine_lifted_cap_, false); }

 private:
  FrameEncodeInputs inputs(const JobShape& shape, bool refine, int live_sessions) const;
  int live_sessions() const;  // sessions open on the server, at least 1

  const FrameSettings& settings_;
  ServerMetrics& metrics_;
  bool av1_ok_ = false;
  int gpu_ = -1;
  bool device_input_ = false;
  std::unique_ptr<Encoder> encoder_;
  int bitrate_kbps_ = 0;            // what encoder_ was built with (the client's Quality)
  int rate_kbps_ = 0;               // its VBV rate now (changed without a rebuild where it can)
  int vbv_ms_ = 0;                  // and its VBV's size, ms of that rate
  bool refine_lifted_cap_ = false;  // the frame being encoded is a refine frame that lifted a VBV cap
  int threads_ = 0;                 // its sliced threads (encoder_policy.h)
  std::string label_;               // Stats.encoder
  int step_ = 0;                    // its step (FrameEncoding::step): the ladder's preset, or kPresetSteps for AV1
  std::chrono::steady_clock::time_point built_{};
  std::string scene_name_;
  std::shared_ptr<ContentRates> content_rates_;  // the scene's (open)
  std::unique_ptr<ContentRateProbe> probe_;      // this session's probe, holding its size's claim
  std::optional<CameraPose> probe_last_pose_;    // the last pose it was fed
};

}  // namespace catgs::server
