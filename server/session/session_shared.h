// What a server's sessions share, and what a session's parts ask of the session that owns them
// (docs/DESIGN.md "Server"). A Session (session.h) is the protocol state machine; its stream
// (session_stream.h: the frame's way, render -> convert -> encode -> send) and its video export
// (session_export.h) are its parts, each on the session's strand.
#pragma once

#include <utility>  // Boost 1.74 Asio under C++20 needs std::exchange declared first

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include <boost/asio/io_context.hpp>
#include <boost/asio/strand.hpp>

#include "process/scene_store.h"
#include "process/server_metrics.h"
#include "proto/message_validation.h"
#include "render/gpu_assignment.h"
#include "render/render_scheduler.h"
#include "renderer/renderer.h"
#include "session/rate_limit.h"
#include "session/session_settings.h"
#include "transport/connection_link.h"

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

using SessionStrand = boost::asio::strand<boost::asio::io_context::executor_type>;

// What a session's parts (its stream, its export) ask of the Session that owns them. Called on
// the session's strand, except keep_alive and strand (any thread).
class SessionOwner {
 public:
  // A reference that keeps the session (and so its parts) alive: jobs queued on the render lanes
  // and the worker pool hold one until their result is back on the strand.
  virtual std::shared_ptr<void> keep_alive() = 0;
  virtual SessionStrand& strand() = 0;
  // The connection is gone or the session failed (any thread): skip work for nobody.
  virtual bool gone() const = 0;
  // "[session ID SESSION_ID]" for the logs.
  virtual std::string label() const = 0;
  virtual void send(const pb::ServerMessage& message) = 0;
  // Ends the session with Error{code, reason} (the last message) and closes.
  virtual void end_session(pb::ErrorCode code, const std::string& reason) = 0;
  // Past Welcome and not closed: frames have someone to go to.
  virtual bool is_open() const = 0;
  // The stream's frames and device memory (issue 61): the renderer's device buffers after a
  // frame (bytes; 0: none reported), and a frame lost because a buffer could not grow, the
  // `streak`-th in a row.
  virtual void on_frame_buffers(std::uint64_t device_bytes, const BufferShape& shape) = 0;
  virtual void on_out_of_memory(const std::string& error, int streak) = 0;

 protected:
  ~SessionOwner() = default;
};

}  // namespace catgs::server
