// One client session (docs/DESIGN.md "Server"): protocol state machine, latest-pose-wins render
// scheduling, flow control and statistics. The protocol state machine (Hello, scene load,
// Welcome, messages, timeouts, Stats) is session.cpp; the stream (when render and encode jobs
// start, pacing, adaptive quality, the link, the Frame handed to the transport) is
// session_stream.cpp; the frame's own state (pose slots, I420 buffers, renderer, encoder) is a
// FramePipeline (frame_pipeline.h).
//
// Threading: every member below "strand state" is touched only on the session's strand. Renders
// run as jobs on the render scheduler's lanes, encodes as jobs on the worker pool (never on the
// strand, so poses keep arriving while a frame renders). Transport callbacks enter through the
// post_* functions.
#pragma once

#include <utility>  // Boost 1.74 Asio under C++20 needs std::exchange declared first

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>

#include "scene/gaussian_model.h"
#include "renderer/renderer.h"
#include "encode/encoder.h"
#include "render/gpu_assignment.h"
#include "render/render_scheduler.h"
#include "session/access_tokens.h"
#include "session/adaptive_quality.h"
#include "session/frame_pacing.h"
#include "session/frame_pipeline.h"
#include "proto/message_validation.h"
#include "process/first_view.h"
#include "session/link_rate.h"
#include "session/rate_limit.h"
#include "session/session_settings.h"
#include "session/still_refine.h"
#include "process/scene_store.h"
#include "session/video_export.h"
#include "process/server_metrics.h"
#include "transport/transport.h"

namespace catgs::server {

// What all sessions share (owned by the Server; it outlives every session).
struct SessionShared {
  boost::asio::io_context& io;  // the worker pool: strands, encode jobs, timers
  RenderScheduler& renders;     // render jobs, sessions in turn (render_scheduler.h)
  GpuAssignment& gpus;          // which GPU a session renders on (CUDA renderer; gpu_assignment.h)
  ConnectionLink& transport;    // the Transport (transport.h); a fake in tests/fuzz/fuzz_session.cpp
  ServerMetrics& metrics;
  const SessionSettings& settings;  // the server holds them for its lifetime
  SceneStore& scenes;               // every --scene, in order, the first the default; loaded on first use
  RenderOptions render_options;
  std::string renderer_kind;  // resolved at start-up: "cpu" or "cuda"
  std::string encoder_kind;   // resolved at start-up: "x264" or "nvenc" (Welcome.encoder)
  // Set by the server when SIGTERM starts the drain: a Hello now gets ERROR_SHUTTING_DOWN, and
  // open sessions' Stats carry the time left until drain_deadline (steady clock).
  std::atomic<bool> draining{false};
  std::atomic<std::chrono::steady_clock::time_point> drain_deadline{};
  // Hello and failed-token limits per client address (a new connection per attempt).
  PeerLimiter peers{settings.rate_limits};
  // The folder of video exports' files (video_export.h export_folder(); set by the server at
  // start-up, empty when exports are off or not built). The exports rendering now, server-wide
  // (--export-max-concurrent), are metrics.exports_running.
  std::string export_folder = {};
  // The device bytes the last visitor's session needed (set at each placement; the server sets
  // the first scene's at 1280x720 at start-up): /readyz answers 503 while no GPU has that room.
  std::atomic<std::uint64_t> next_session_bytes{0};
};

// Error.retry_after_ms hints, ms. Each Error carries base .. 2 x base, drawn uniformly, so the
// sessions a drain ends at once do not all reconnect in the same instant.
// SERVER_FULL: a full pod turns not-ready (/readyz) within a readiness period (2 s in deploy/k8s),
// after which the Service sends the reconnect elsewhere.
constexpr std::uint32_t kServerFullRetryMs = 2000;
// SHUTTING_DOWN: a draining pod is already out of the Service's endpoints; come back soon.
constexpr std::uint32_t kShuttingDownRetryMs = 500;

class Session : public std::enable_shared_from_this<Session> {
 public:
  // A connection waiting for Hello. The session slot (settings.max_sessions) is taken at Hello.
  Session(ConnId id, SessionShared& shared);
  ~Session();

  ConnId id() const { return id_; }
  // Starts the Hello clock (--hello-timeout-ms). Call once, right after construction.
  void start();
  // Transport thread -> strand: a complete incoming message.
  void post_message(MessageKind kind, std::string bytes);
  // Transport thread -> strand: a Frame left the queue (written to the socket layer); `socket`
  // is the socket's TCP_INFO right after (link_rate.h).
  void post_sent(const SocketSample& socket = {});
  // Transport thread -> strand: the connection is gone.
  void post_closed();
  // Server stopping (the drain's end): send ERROR_SHUTTING_DOWN with a retry hint and close.
  void post_shutdown();

 private:
  using Clock = std::chrono::steady_clock;
  // loading: past Hello, waiting for its scene to load (SceneStore::acquire); holds a session slot.
  enum class State { awaiting_hello, loading, open, closed };

  using JobResult = FramePipeline::JobResult;
  // A frame handed to the transport.
  struct Handed {
    Clock::time_point at;         // when it went to the transport
    std::size_t bytes;            // its message's size
    std::uint32_t sequence = 0;   // Frame.sequence
    Clock::time_point rate_at{};  // when its encoder's rate was read (JobShape::link_read_at)
    bool refine = false;          // the still view's refine frame (still_refine.h)
    Clock::time_point written{};  // when the kernel took its last byte (post_sent; {} until then)
  };

  // `received`: when the transport thread handed the message over.
  void handle_message(MessageKind kind, const std::string& bytes, Clock::time_point received);
  void handle_hello(const pb::Hello& hello);
  // The scene's load ended (on the strand): Welcome and the stream, or Error naming the file.
  void on_scene_ready(std::shared_ptr<const LoadedScene> scene, const std::string& error);
  // While the scene loads: LoadProgress to a client that asked for it (Hello.load_progress).
  void send_load_progress(int percent, std::uint64_t done, std::uint64_t total);
  void handle_pose(const pb::Pose& pose, Clock::time_point received);
  // DepthRequest: validated here, probed on the worker pool (depth_probe.h), answered on the strand.
  void handle_depth(const pb::DepthRequest& request);
  // SaveAnnotations: an author's hotspots written beside the scene (annotations.h).
  void handle_save_annotations(const pb::SaveAnnotations& save);
  // ExportVideoRequest / ExportCancel, and the export's steps (export_pipeline.cpp): validated
  // and authorised here, one frame per background job on the render lanes, progress to the page,
  // then the file in chunks.
  void handle_export(const pb::ExportVideoRequest& request);
  // Whether this session's requests would get past the build, folder and role checks (Welcome's
  // can_export): the page hides what the server would refuse anyway.
  bool may_export() const;
  void handle_export_cancel(const pb::ExportCancel& cancel);
  void post_export_step();  // the export's next frame, at low priority
  // On the strand: a step of `video` ended (finished: the file is complete; error: it failed).
  void on_export_step(const std::shared_ptr<VideoExport>& video, bool finished, const std::string& error);
  // The running export's state (ExportProgress); `error` / `cancelled`: how it ended.
  void send_export_progress(const std::string& error = {}, bool cancelled = false);
  void refuse_export(std::uint32_t export_id, const std::string& why);  // ExportProgress.error
  void send_export_chunks();  // the finished file's next chunks, a few queued at a time
  // Ends the session's export: its slot (if still rendering) and its file go.
  void end_export(ServerMetrics::ExportEnd how);
  // Annotations after Welcome: the file beside the scene, or its error (the scene opens anyway).
  void send_annotations();
  // --adaptive-quality, on the tick: applies AdaptiveQuality's rule.
  void adapt_quality(Clock::time_point now);
  // On the tick: the still view's refine frame when it is due (still_refine.h).
  void refine_still_view(Clock::time_point now);
  // A frame (handed at frame.at) was written at `written`: the link's rate controller and, with
  // --adaptive-quality, the level's link input (link_rate.h, adaptive_quality.h).
  void on_link_sample(const Handed& frame, Clock::time_point written, const SocketSample& socket);
  // The encoder's VBV rate for a width x height frame the link's cap sets now (link_rate.h), at
  // the nominal kStreamFps; 0 where the link does not limit. Updates link_ceiling_kbps_.
  int link_vbv_kbps(int width, int height);
  // What a link update (a frame written, a receipt) changed: the metrics, the socket's send
  // buffer, adaptive quality's view of the link.
  void after_link_update(bool was_limited, int cuts);
  // Pose.received_frame_sequence / received_ms: the client's receipt for a frame, to the link's
  // controller.
  void on_receipt(std::uint32_t sequence, double received_ms, Clock::time_point now);
  // Ends the session with Error{code, reason, retry_after_ms} (the last message) and closes;
  // retry_after_ms is the client's reconnect hint (0: none).
  void fail(pb::ErrorCode code, const std::string& reason, bool drop_queued = false, std::uint32_t retry_after_ms = 0);
  void send(const pb::ServerMessage& message);
  void maybe_start_render();
  void maybe_start_encode();
  void on_job_done(JobResult result);
  void arm_tick();
  void on_tick();
  void send_stats();
  void end_open_state();
  // Takes one token of `bucket` for a message of kind `limit`; past the limit, ends the session
  // with ERROR_RATE_LIMITED (counted) and returns false.
  bool within(TokenBucket& bucket, ServerMetrics::Limit limit, const char* what, const RateSpec& spec);
  // Hello's access checks: the per-address Hello limit and the token (with its own limit on
  // failures). Ends the session and returns false when refused.
  bool admit(const pb::Hello& hello);
  ViewportLimit viewport_limit() const;  // --max-viewport

  const ConnId id_;
  SessionShared& shared_;
  boost::asio::strand<boost::asio::io_context::executor_type> strand_;
  boost::asio::steady_timer tick_;
  boost::asio::steady_timer hello_timer_;  // --hello-timeout-ms, then --scene-load-timeout-ms
  const std::string peer_;                 // client address (per-address limits, logs)

  // Set when the connection is gone or the session failed (any thread): render jobs still queued
  // for this session are skipped rather than rendered for nobody.
  std::atomic<bool> gone_{false};

  // --- strand state ---
  State state_ = State::awaiting_hello;
  bool counted_open_ = false;  // holds one of the server's session slots
  std::string session_id_;
  std::unique_ptr<SceneStore::Use> scene_use_;  // from Hello until the session ends: keeps it loaded
  std::shared_ptr<const LoadedScene> scene_;    // once loaded
  bool load_progress_ = false;                  // Hello.load_progress
  bool client_av1_ = false;                     // Hello.codecs lists AV1
  std::string client_name_;                     // Hello.client_name (logs), at most 128 bytes
  int progress_sent_ = -1;                      // the last LoadProgress percent sent
  int width_ = 0, height_ = 0;
  int max_bitrate_kbps_ = 0;                         // the client's Quality
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
  int link_ceiling_kbps_ = 0;        // the policy's rate for the last job's size (link_rate.h's ceiling)
  int send_buffer_ = 0;              // the socket's SO_SNDBUF as the session last set it (0: the transport's)
  double last_send_ms_ = 0;          // send time of the last frame written
  Clock::time_point last_progress_;  // last time the transport wrote one of our frames
  Clock::time_point last_stats_;
  Clock::time_point last_message_;  // the client's latest message (--silent-timeout-ms)
  TokenBucket ping_bucket_, key_frame_bucket_, resize_bucket_, quality_bucket_;  // --rate-limits
  TokenBucket depth_bucket_, save_bucket_;                                       // --rate-limits
  Role role_ = Role::none;               // the Hello token's role (none: the server has no tokens)
  std::optional<CameraPose> last_pose_;  // the newest valid Pose (a DepthRequest without one)
  int depths_in_flight_ = 0;             // DepthRequests probing on the pool
  TokenBucket export_bucket_;            // --rate-limits export
  // The session's video export (one at a time): rendering (a step job in flight or not), then
  // sending its file. Null when there is none.
  struct Export {
    std::shared_ptr<VideoExport> video;
    bool holds_slot = false;  // counts in metrics.exports_running (while rendering)
    bool sending = false;     // finished: its file goes out in chunks
    Clock::time_point started, last_progress;
    std::unique_ptr<std::ifstream> file;
    double size = 0, sent = 0;  // bytes
  };
  std::unique_ptr<Export> export_;
  // Stats counters (totals, and sums since the last Stats message).
  std::uint32_t frames_sent_ = 0, poses_received_ = 0, poses_skipped_ = 0, key_frames_ = 0;
  std::uint32_t render_key_frames_ = 0, render_sub_frames_ = 0;  // speculation (catgs)
  double render_ms_sum_ = 0, encode_ms_sum_ = 0;
  double lod_error_px_sum_ = 0, splats_sum_ = 0;  // the interval's frames' LOD bounds and Gaussians
  std::uint32_t frames_since_stats_ = 0;
  std::uint64_t bytes_since_stats_ = 0;

  FramePipeline frames_;  // the frame's state: pose slots, I420 buffers, renderer, encoder
  int gpu_ = -1;          // the CUDA device the session renders on (shared_.gpus), -1: none (CPU)
  // Device memory (issue 61; gpu_assignment.h): whether this session holds a place in
  // shared_.gpus, and the bytes it reserves there: the estimate for its viewport
  // (memory_estimate), raised to what its renderer's buffers grew to.
  bool placed_ = false;
  std::uint64_t memory_reserved_ = 0, memory_peak_ = 0;
  std::uint64_t memory_estimate(int width, int height) const;
  void update_memory(std::uint64_t buffer_bytes);
  void on_out_of_memory(const std::string& error);
  static constexpr int kMaxOutOfMemoryFrames = 64;
  int out_of_memory_streak_ = 0;
};

}  // namespace catgs::server
