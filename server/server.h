// The catgs-server process (DESIGN.md "Server"): the scene, the renderer and encoder chosen once
// for every session, the worker pool, the render scheduler, the transport, the session manager,
// the signal handling and the orderly shutdown. main.cpp parses the options and runs a Server.
//
// Threads: the constructor and run() belong to one thread (main's). run() starts the lws service
// thread (Transport), ServerOptions::threads workers on one io_context (session strands, encode
// jobs, timers) and the render lanes (RenderScheduler), and blocks until SIGINT or SIGTERM.
#pragma once

#include <utility>  // Boost 1.74 Asio under C++20 needs std::exchange declared first

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "renderer/renderer.h"
#include "render/render_scheduler.h"
#include "scene/gaussian_model.h"
#include "server_metrics.h"
#include "server_options.h"
#include "session/session.h"
#include "session/session_manager.h"
#include "transport/transport.h"

namespace catgs::server {

class Server {
 public:
  // Loads options.scene, then resolves the renderer and the encoder once (an "auto" choice and
  // the NVENC probe happen here), printing the scene, renderer and encoder lines on stdout.
  // Nothing listens and no thread starts yet. `options` must outlive the server. Throws what
  // load_scene, make_renderer and make_encoder throw (std::runtime_error for a file or codec
  // that cannot be opened, std::invalid_argument for an unknown name).
  explicit Server(const ServerOptions& options);
  // Stops the threads that run() left running (it threw after they started).
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Listens, starts the pools, prints the "listening on" line, blocks until SIGINT or SIGTERM,
  // then shuts down: sessions get ERROR_SHUTTING_DOWN, the transport stops, the render lanes
  // drain, then the worker pool; prints the totals. Returns the process exit code (0). Throws
  // std::runtime_error when the port cannot be bound (before any thread starts). Call once.
  int run();

 private:
  // Transport callbacks (service thread) to the session manager, which is built after the
  // transport because the sessions' shared state names the transport.
  struct ToManager final : TransportHandler {
    SessionManager* manager = nullptr;
    void on_open(ConnId id) override;
    void on_message(ConnId id, MessageKind kind, std::string bytes) override;
    void on_sent(ConnId id) override;
    void on_close(ConnId id) override;
    std::string metrics_text() override;
  };
  using Deadline = std::chrono::steady_clock::time_point;

  // Start-up, in this order.
  void load_model();
  void resolve_renderer();
  void resolve_encoder();
  void build_sessions();
  void catch_signals();
  void start_pools();
  void print_listening() const;
  // Blocks until SIGINT or SIGTERM.
  void wait_for_signal();
  // Shutdown, in this order.
  void shut_down();
  void drain_workers(Deadline deadline);
  void stop_pools();
  void run_leftovers();
  void print_totals() const;

  const ServerOptions& options_;
  ServerMetrics metrics_;
  std::shared_ptr<const GaussianModel> model_;
  RenderOptions render_options_;
  std::string renderer_kind_;  // "cpu" or "cuda"
  std::string encoder_kind_;   // "x264" or "nvenc"
  // Declared before everything that holds sessions: strands and timers live in it, and queued
  // handlers hold sessions, so it must outlive them.
  boost::asio::io_context io_;
  RenderScheduler renders_;
  ToManager to_manager_;
  std::unique_ptr<Transport> transport_;
  std::unique_ptr<SessionShared> shared_;
  std::unique_ptr<SessionManager> manager_;
  std::optional<boost::asio::executor_work_guard<boost::asio::io_context::executor_type>> work_;
  std::vector<std::thread> workers_;
  // Signals are waited for on their own io_context so the pool keeps serving meanwhile.
  boost::asio::io_context signal_io_;
  std::optional<boost::asio::signal_set> signals_;
};

}  // namespace catgs::server
