// The catgs-server process (docs/DESIGN.md "Server"): the scene, the renderer and encoder chosen
// once for every session, the worker pool, the render scheduler, the transport, the session
// manager, the signal handling and the orderly shutdown. main.cpp parses the options and runs a
// Server.
//
// Threads: the constructor and run() belong to one thread (main's). run() starts the lws service
// thread (Transport), ServerOptions::threads workers on one io_context (session strands, encode
// jobs, timers) and the render lanes (RenderScheduler), and blocks until SIGINT or SIGTERM.
//
// Phases, as /readyz reports them (capacity-aware routing: a load balancer sends new users only
// to pods that answer 200; /healthz stays 200 throughout, so liveness never kills a loading or
// draining server):
//   loading   HTTP listens first, then the renderer is resolved, the first scene loads and the
//             encoder is resolved (the other scenes load later, on first use):
//             /readyz 503 "loading"; a WebSocket gets ERROR_SERVER_FULL with a retry hint.
//   serving   /readyz 200, or 503 "full" while --max-sessions sessions are open.
//   draining  SIGTERM: /readyz 503 "draining", every new Hello gets ERROR_SHUTTING_DOWN, live
//             sessions keep streaming until they leave or --drain-timeout-s passes. Live sessions
//             are told ERROR_SHUTTING_DOWN (with retry_after_ms) at the drain's end, not its
//             start: an Error ends a session (protocol), and telling them at the start would cut
//             every user off at once, which is what the drain exists to avoid.
//   stopping  the rest get ERROR_SHUTTING_DOWN, the transport and the pools stop, exit code 0.
// SIGINT (an operator's Ctrl-C) or a second SIGTERM skips the rest of the drain. SIGHUP while
// serving or draining (one during loading waits until serving) re-reads --tls-cert / --tls-key
// (Transport::reload_tls): sessions stay, and a bad file is logged while the previous
// certificate stays in use.
#pragma once

#include <utility>  // Boost 1.74 Asio under C++20 needs std::exchange declared first

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>

#include <atomic>
#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "renderer/renderer.h"
#include "render/render_scheduler.h"
#include "scene/gaussian_model.h"
#include "process/server_metrics.h"
#include "server_options.h"
#include "process/first_view.h"
#include "session/session.h"
#include "process/scene_store.h"
#include "session/session_manager.h"
#include "transport/transport.h"

namespace catgs::server {

class Server {
 public:
  // Nothing loads, listens or starts yet. `options` must outlive the server.
  explicit Server(const ServerOptions& options);
  // Stops the threads that run() left running (it threw after they started).
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Listens (printing "probes on http://ADDR:PORT/"), resolves the renderer once (an "auto"
  // choice happens here), lists every --scene and loads the first (the others load on first use:
  // process/scene_store.h), resolves the encoder (the NVENC probe), printing the renderer, scene
  // and encoder lines; starts the pools, prints the "listening on" line
  // (from here sessions are admitted), blocks until SIGINT or SIGTERM, drains (see above), then
  // shuts down: remaining sessions get ERROR_SHUTTING_DOWN, the transport stops, the render
  // lanes drain, then the worker pool; prints the totals. Returns the process exit code (0).
  // Throws std::runtime_error when the port cannot be bound (before any thread starts), and
  // what SceneStore (two scenes of one name), load_scene (the first scene), make_renderer and
  // make_encoder throw (std::runtime_error for a file, GPU or codec that cannot be had,
  // std::invalid_argument for an unknown name). Call once.
  int run();

 private:
  // Transport callbacks (service thread) to the session manager, which is built after the
  // transport because the sessions' shared state names the transport.
  // Until the manager exists (the loading phase) it answers for it: /readyz 503, WebSockets
  // refused with a retry hint.
  struct ToManager final : TransportHandler {
    std::atomic<SessionManager*> manager{nullptr};
    Transport* transport = nullptr;
    const ServerOptions* options = nullptr;
    ServerMetrics* metrics = nullptr;
    void on_open(ConnId id) override;
    void on_message(ConnId id, MessageKind kind, std::string bytes) override;
    void on_sent(ConnId id, const SocketSample& socket) override;
    void on_close(ConnId id) override;
    std::string metrics_text() override;
    int readiness(std::string& body) override;
    int metrics_access(const std::string& authorization) override;
    std::string scenes_json() override;
    void on_refused(Refusal why, const std::string& peer, const std::string& detail) override;
  };
  using Deadline = std::chrono::steady_clock::time_point;

  // Start-up, in this order.
  void resolve_renderer();
  // --gpus: the GPUs of the CUDA renderer (none on the CPU).
  void resolve_gpus();
  // The scene store over every --scene (listed from headers), and the first scene loaded (with
  // a copy on each GPU).
  void load_model();
  void resolve_encoder();
  void build_sessions();
  void catch_signals();
  void start_pools();
  void print_listening() const;
  // Clears last_signal_ and waits for the next signal (run signal_io_ to receive it).
  void arm_signals();
  // "http" -> "https", "ws" -> "wss" when the transport speaks TLS.
  std::string url_scheme(const std::string& plain) const;
  // The "tls:" line: the certificate file and TlsCredentials::describe() (nothing without TLS).
  void print_tls() const;
  // SIGHUP: Transport::reload_tls, logged; a bad file is logged and the old certificate stays.
  void reload_tls();
  // Blocks until SIGINT or SIGTERM (reloading on each SIGHUP meanwhile); returns the signal.
  int wait_for_signal();
  // SIGTERM: not ready, no new sessions, live ones go on until they leave, the timeout passes
  // or another signal comes.
  void drain();
  // Shutdown, in this order.
  void shut_down();
  void drain_workers(Deadline deadline);
  void stop_pools();
  void run_leftovers();
  void print_totals() const;

  const ServerOptions& options_;
  ServerMetrics metrics_;
  RenderOptions render_options_;
  std::string renderer_kind_;  // "cpu" or "cuda"
  std::string encoder_kind_;   // "x264" or "nvenc"
  // The GPUs sessions render on (--gpus; none with the CPU renderer) and the scenes (each loaded
  // one holds a renderer per GPU, so each GPU keeps one copy of it between sessions). Declared
  // before io_: sessions, which io_'s handlers may hold to the end, use both.
  std::unique_ptr<GpuAssignment> gpus_;
  std::unique_ptr<SceneStore> scenes_;
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
  int last_signal_ = 0;  // set by the signal handler (on this thread, in signal_io_)
};

}  // namespace catgs::server
