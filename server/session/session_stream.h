// A session's stream: the frame's way from a pose to the client, stage by stage
// (docs/DESIGN.md "Data flow of a frame"), and what decides when each stage may start.
//
//   stage      runs on            does                                        next
//   admit      the strand         latest pose wins; frames in flight bound    render
//   render     a render lane      FramePipeline::begin_render: the frame queued rendered
//                                 on the GPU; the lane's Finish (finish_render)
//                                 waits for its I420 planes, as the lane sees fit
//                                 (render_scheduler.h "Frames in flight")
//   rendered   the strand         pacing, the rendered slot                   encode
//   encode     the worker pool    FramePipeline::encode: the frame's encoder  hand_off
//                                 settings (encode/frame_encoding.h), the
//                                 access unit, the Frame message
//   hand_off   the strand         counted, handed to the transport            sent
//   sent       the strand         post_sent: the link's rate controller       admit
//
// With NVENC and the CUDA renderer, render and encode are one job (render_and_encode) on a lane.
// A rendered frame that would miss its display slot while a newer pose waits is skipped before
// its encode (frame_pacing.h). The stream also holds what the written frames and the client's
// receipts say about the link (link_rate.h), adaptive quality's level (adaptive_quality.h), the
// still view's refine frame (still_refine.h) and the Stats counters.
//
// Threading: every public function on the session's strand. Jobs hold the session alive
// (SessionOwner::keep_alive) until their result is back on the strand.
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>

#include "camera/camera.h"
#include "session/adaptive_quality.h"
#include "session/frame_pacing.h"
#include "session/frame_pipeline.h"
#include "session/link_rate.h"
#include "session/pose_prediction.h"
#include "session/session_shared.h"
#include "session/still_refine.h"

namespace catgs::server {

class SessionStream {
 public:
  using Clock = std::chrono::steady_clock;

  SessionStream(SessionShared& shared, ConnId id, SessionOwner& owner);
  ~SessionStream();
  SessionStream(const SessionStream&) = delete;
  SessionStream& operator=(const SessionStream&) = delete;

  // At Welcome: the frame pipeline's renderer and encoder path (FramePipeline::open).
  void open(std::unique_ptr<Renderer> renderer, std::shared_ptr<const GaussianModel> model, int gpu, bool pipelined,
            bool av1_ok, std::shared_ptr<ContentRates> content_rates);
  // Whether the first frame would be AV1 (Welcome.codec) at `live_sessions`.
  bool first_frame_av1(int live_sessions) const;
  std::string renderer_name() const { return frames_.renderer_name(); }

  // The client's viewport (Hello, Resize; pixels). A new size makes the next frame an IDR.
  void set_viewport(int width, int height);
  int width() const { return width_; }
  int height() const { return height_; }
  // Quality.max_bitrate_kbps (0: the server's default); the next frame is an IDR.
  void set_max_bitrate(int kbps);
  // KeyFrameRequest: the next frame is an IDR.
  void request_idr() { frames_.request_idr(); }

  // A valid Pose (`cam`, and a headset's `eyes`), received on the transport thread at `received`:
  // its receipt for an earlier frame, the client's shown latency, then the pose offered (latest
  // wins). A stereo pose is drawn as sent: the page re-projects each eye to the head's newest pose.
  void on_pose(const pb::Pose& pose, const CameraPose& cam, const std::optional<StereoPose>& eyes,
               Clock::time_point received);
  // The admit stage: starts a render job when a pose waits and a slot is free.
  void admit();
  // The transport wrote a Frame (stamped on its thread at `written`; `socket`: TCP_INFO then).
  void on_sent(Clock::time_point written, const SocketSample& socket);
  // On the session's tick: adaptive quality's rule and the still view's refine frame.
  void on_tick(Clock::time_point now);
  // Frames handed to the transport and not yet written, and whether the oldest waits past
  // `timeout` (a client that stopped reading).
  bool unread_for(Clock::time_point now, std::chrono::milliseconds timeout) const;
  // Stats' stream fields over the last `seconds`; starts the next interval.
  void fill_stats(pb::Stats& stats, double seconds);
  // The session is opened (Welcome sent): the slow-reader clock starts now.
  void opened(Clock::time_point now) { last_progress_ = now; }
  // The session ends: the pose waiting is never rendered. True when there was one.
  bool drop_pending() { return frames_.drop_pending(); }
  // After a frame lost for device memory: the render list's budget halved (bytes now).
  std::uint64_t halve_list_budget() { return frames_.halve_list_budget(); }
  // The lost frame's pose again where no newer one waits (FramePipeline::retry_lost).
  void retry_lost_frame() { frames_.retry_lost(); }

 private:
  using JobResult = FramePipeline::JobResult;
  // A frame handed to the transport.
  struct Handed {
    Clock::time_point at;         // when it went to the transport
    std::size_t bytes;            // its message's size
    std::uint32_t sequence = 0;   // Frame.sequence
    Clock::time_point rate_at{};  // when its encoder's rate was read (JobShape::link_read_at)
    bool refine = false;          // the still view's refine frame (still_refine.h)
    Clock::time_point written{};  // when the kernel took its last byte (on_sent; {} until then)
  };

  // The stages (the table above).
  RenderScheduler::Finish render(FramePipeline::StartedRender started);  // a render lane
  void rendered(FramePipeline::Rendered frame);                          // the strand
  void start_encode();                                                   // the strand
  void encode(const std::shared_ptr<FramePipeline::Rendered>& frame);    // the worker pool
  void render_and_encode(const FramePipeline::Job& job);                 // a lane (NVENC's one job)
  void hand_off(JobResult result);                                       // the strand
  void count(const JobResult& result);                                   // Stats and /metrics

  // The link's state now, for the frame's encoder settings (frame_encoding's input, which turns it
  // into the encoder's cap once a frame, at its encode).
  LinkInputs link_inputs() const;
  // A frame (handed at frame.at) was written at `written`: the link's rate controller.
  void on_link_sample(const Handed& frame, Clock::time_point written, const SocketSample& socket);
  // What a link update (a frame written, a receipt) changed: the metrics, the socket's send
  // buffer, adaptive quality's view of the link.
  void after_link_update(bool was_limited, int cuts);
  // Pose.received_frame_sequence / received_ms: the client's receipt for a frame.
  void on_receipt(std::uint32_t sequence, double received_ms, Clock::time_point now);

  SessionShared& shared_;
  const ConnId id_;
  SessionOwner& owner_;
  FramePipeline frames_;  // the frame's state: pose slots, I420 buffers, renderer, encoder
  int gpu_ = -1;          // the CUDA device it renders on (open), -1: the CPU renderer
  int width_ = 0, height_ = 0;
  int max_bitrate_kbps_ = 0;                         // the client's Quality
  PosePrediction prediction_;                        // --pose-prediction
  AdaptiveQuality quality_;                          // --adaptive-quality
  FramePacing pacing_;                               // --frame-deadline
  StillRefine still_;                                // the still view's refine frame
  int in_flight_ = 0;                                // frames queued to the transport, not yet written
  std::deque<Handed> handed_;                        // the in-flight frames, in order
  static constexpr std::size_t kRecentFrames = 256;  // about 4 s at 60 frames/s
  std::deque<Handed> recent_;                        // the last kRecentFrames handed, for the client's receipts
  std::uint32_t last_receipt_ = UINT32_MAX;          // the newest receipt's frame (none yet)
  LinkRate link_;                                    // the link's rate controller (--link-control)
  int cuts_by_cause_[LinkRate::kCauses] = {};        // link_'s cuts by cause, counted in /metrics
  int link_ceiling_kbps_ = 0;        // the last frame's FrameEncoding::link_ceiling_kbps (link_rate.h's ceiling)
  int send_buffer_ = 0;              // the socket's SO_SNDBUF as the stream last set it (0: the transport's)
  double last_send_ms_ = 0;          // send time of the last frame written
  double display_hz_ = 0;            // the client's display rate (Pose.display_hz; 0: unknown)
  Clock::time_point last_progress_;  // last time the transport wrote one of our frames
  // Stats counters (totals, and sums since the last Stats message).
  std::uint32_t frames_sent_ = 0, poses_received_ = 0, poses_skipped_ = 0, key_frames_ = 0;
  std::uint32_t render_key_frames_ = 0, render_sub_frames_ = 0;  // speculation (catgs)
  double render_ms_sum_ = 0, encode_ms_sum_ = 0;
  // The encoder's picture (Stats.encode_psnr_db_mean: the frames that measured it) and its name.
  double encode_psnr_sum_ = 0;
  std::uint32_t encode_psnr_frames_ = 0;
  std::string encoder_;
  // The interval's frames drawn after a buffer could not grow (Stats.memory_fallback_frames) and
  // the last one's reason.
  std::uint32_t memory_fallbacks_ = 0;
  std::string memory_note_;
  double lod_error_px_sum_ = 0, splats_sum_ = 0;  // the interval's frames' LOD bounds and Gaussians
  std::uint32_t frames_since_stats_ = 0;
  std::uint64_t bytes_since_stats_ = 0;
  int out_of_memory_streak_ = 0;  // frames lost in a row because a device buffer could not grow
};

}  // namespace catgs::server
