// One client session (docs/DESIGN.md "Server"): the protocol state machine (Hello, scene load,
// Welcome, messages, timeouts, Stats), the session's place on a GPU (device memory), and its two
// parts: the stream (session_stream.h: the frame's way from a pose to the client, stage by stage)
// and the video export (session_export.h).
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
#include <memory>
#include <optional>
#include <string>

#include <boost/asio/steady_timer.hpp>

#include "camera/camera.h"
#include "process/scene_store.h"
#include "proto/message_validation.h"
#include "session/access_tokens.h"
#include "session/rate_limit.h"
#include "session/session_export.h"
#include "session/session_shared.h"
#include "session/session_stream.h"

namespace catgs::server {

// Error.retry_after_ms hints, ms. Each Error carries base .. 2 x base, drawn uniformly, so the
// sessions a drain ends at once do not all reconnect in the same instant.
// SERVER_FULL: a full pod turns not-ready (/readyz) within a readiness period (2 s in deploy/k8s),
// after which the Service sends the reconnect elsewhere.
constexpr std::uint32_t kServerFullRetryMs = 2000;
// SHUTTING_DOWN: a draining pod is already out of the Service's endpoints; come back soon.
constexpr std::uint32_t kShuttingDownRetryMs = 500;

class Session : public std::enable_shared_from_this<Session>, private SessionOwner {
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
  // ExportVideoRequest: rate limited here, then the export's (session_export.h).
  void handle_export(const pb::ExportVideoRequest& request);
  // Annotations after Welcome: the file beside the scene, or its error (the scene opens anyway).
  void send_annotations();
  // Ends the session with Error{code, reason, retry_after_ms} (the last message) and closes;
  // retry_after_ms is the client's reconnect hint (0: none).
  void fail(pb::ErrorCode code, const std::string& reason, bool drop_queued = false, std::uint32_t retry_after_ms = 0);
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

  // SessionOwner (session_shared.h): what the stream and the export ask of the session.
  std::shared_ptr<void> keep_alive() override { return shared_from_this(); }
  SessionStrand& strand() override { return strand_; }
  bool gone() const override { return gone_; }
  std::string label() const override;
  void send(const pb::ServerMessage& message) override;
  void end_session(pb::ErrorCode code, const std::string& reason) override { fail(code, reason); }
  bool is_open() const override { return state_ == State::open; }
  void on_frame_buffers(std::uint64_t device_bytes, const BufferShape& shape) override {
    update_memory(device_bytes, shape);
  }
  void on_out_of_memory(const std::string& error, int streak) override;

  const ConnId id_;
  SessionShared& shared_;
  SessionStrand strand_;
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
  Clock::time_point last_stats_;
  Clock::time_point last_message_;  // the client's latest message (--silent-timeout-ms)
  TokenBucket ping_bucket_, key_frame_bucket_, resize_bucket_, quality_bucket_;  // --rate-limits
  TokenBucket depth_bucket_, save_bucket_;                                       // --rate-limits
  Role role_ = Role::none;               // the Hello token's role (none: the server has no tokens)
  std::optional<CameraPose> last_pose_;  // the newest valid Pose (a DepthRequest without one)
  int depths_in_flight_ = 0;             // DepthRequests probing on the pool
  TokenBucket export_bucket_;            // --rate-limits export
  SessionStream stream_;                 // the frame's way: pose -> render -> encode -> the client
  SessionExport exports_;                // the video export, one at a time
  int gpu_ = -1;                         // the CUDA device the session renders on (shared_.gpus), -1: none (CPU)
  // Device memory (issue 61; gpu_assignment.h): whether this session holds a place in
  // shared_.gpus, and the bytes it reserves there: the estimate for its viewport
  // (memory_estimate), raised to what its renderer's buffers grew to.
  // memory_held_: what its renderer's buffers hold (GpuAssignment::hold: the driver's room counts
  // the rest of its reservation as still to come).
  bool placed_ = false;
  std::uint64_t memory_reserved_ = 0, memory_peak_ = 0, memory_held_ = 0;
  std::uint64_t memory_estimate(int width, int height) const;
  // After a frame (or the door's reservation): the buffers' bytes (0: none reported) and shape.
  void update_memory(std::uint64_t buffer_bytes, const BufferShape& shape = {});
  // The GPU's sessions drew at --lod-max-error over their splat budget within the last
  // kBudgetShortMs (render/lod_bound.h, issue 72): another would slow them all or, without the
  // ceiling, blur every view. Refuses this visitor (ERROR_SERVER_FULL) and returns true.
  bool splat_budget_full();
  static constexpr std::int64_t kBudgetShortMs = 2000;
  // At the door (issue 73): the renderer's buffers for the viewport and the scene's measured peak
  // (LoadedScene::session_shape_peak) allocated now. False: they did not fit, and the visitor
  // was refused (ERROR_SERVER_FULL, its reservation given back).
  bool reserve_buffers(Renderer& renderer);
  static constexpr int kMaxOutOfMemoryFrames = 64;
};

}  // namespace catgs::server
