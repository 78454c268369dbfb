#include "speculation/settings.h"
#include "server.h"

#include <csignal>
#include <iostream>

#include "encode/encoder.h"
#include "scene/ply_io.h"
#include "session/initial_pose.h"

namespace catgs::server {

namespace {

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

TransportOptions transport_options(const ServerOptions& options) {
  TransportOptions t;
  t.bind = options.bind;
  t.port = options.port;
  t.web_root = options.web_root;
  t.socket_send_buffer = options.socket_send_buffer;
  return t;
}

}  // namespace

void Server::ToManager::on_open(ConnId id) { manager->on_open(id); }
void Server::ToManager::on_message(ConnId id, MessageKind kind, std::string bytes) {
  manager->on_message(id, kind, std::move(bytes));
}
void Server::ToManager::on_sent(ConnId id) { manager->on_sent(id); }
void Server::ToManager::on_close(ConnId id) { manager->on_close(id); }
std::string Server::ToManager::metrics_text() { return manager->metrics_text(); }

Server::Server(const ServerOptions& options) : options_(options) {
  load_model();
  resolve_renderer();
  resolve_encoder();
  build_sessions();
}

// After a normal run() there is nothing left to stop; this is for a run() that threw. The
// transport goes first: its service thread calls into the manager, destroyed before it.
Server::~Server() {
  if (transport_) transport_->stop();
  stop_pools();
}

int Server::run() {
  catch_signals();
  // Listen first: a busy port then fails before any thread exists. Work posted before the
  // pools start just waits in their io_contexts.
  transport_->start();
  start_pools();
  print_listening();
  wait_for_signal();
  shut_down();
  print_totals();
  return 0;
}

void Server::load_model() {
  const auto t0 = std::chrono::steady_clock::now();
  model_ = std::make_shared<const GaussianModel>(load_scene(options_.scene));
  std::cout << "scene: " << options_.scene << " (" << model_->name << "), " << model_->size()
            << " Gaussians, SH degree " << model_->sh_degree << ", loaded in " << ms_since(t0) << " ms\n";
}

void Server::resolve_renderer() {
  render_options_.pipeline = parse_pipeline(options_.pipeline);
  apply_speculation_settings(render_options_.speculation, options_.speculation);
  // Resolved once so every session uses the same core, and the log says why.
  std::string why;
  renderer_kind_ = make_renderer(options_.renderer, model_, render_options_, &why)->name();
  std::cout << "renderer: " << renderer_kind_ << " (" << why << "), pipeline "
            << pipeline_name(render_options_.pipeline) << "\n";
}

void Server::resolve_encoder() {
  // An encoder at a small size: "auto" probes NVENC here, once per process. Sessions ask for
  // options.encoder again and get the same verdict.
  EncoderConfig probe;
  probe.width = 256;
  probe.height = 256;
  std::string why;
  bool fell_back = false;
  encoder_kind_ = make_encoder(options_.encoder, probe, &why, &fell_back)->name();
  if (fell_back) metrics_.encoder_fallbacks_total++;
  std::cout << "encoder: " << encoder_kind_ << " (" << why << "), crf " << options_.crf << "\n";
  metrics_.renderer = renderer_kind_;
  metrics_.encoder = encoder_kind_;
  metrics_.pipeline = pipeline_name(render_options_.pipeline);
}

void Server::build_sessions() {
  transport_ = std::make_unique<Transport>(transport_options(options_), to_manager_);
  shared_ = std::unique_ptr<SessionShared>(new SessionShared{io_, renders_, *transport_, metrics_, options_, model_,
                                                             model_->bounds(), first_view_bounds(*model_),
                                                             render_options_, renderer_kind_, encoder_kind_});
  manager_ = std::make_unique<SessionManager>(*shared_);
  to_manager_.manager = manager_.get();
}

void Server::catch_signals() {
  // SIGINT/SIGTERM are caught from here on (one that arrives before wait_for_signal() is kept).
  // Registered before the "listening" line: a supervisor that stops the server right after it
  // gets a clean shutdown.
  signals_.emplace(signal_io_, SIGINT, SIGTERM);
}

void Server::start_pools() {
  work_.emplace(io_.get_executor());
  for (int i = 0; i < options_.threads; ++i) workers_.emplace_back([this] { io_.run(); });
  renders_.start(RenderScheduler::default_lanes(options_.render_lanes, renderer_kind_, options_.threads),
                 options_.max_pixels_in_flight);
}

void Server::print_listening() const {
  std::cout << "web root: " << options_.web_root << "\n"
            << "sessions: at most " << options_.max_sessions << ", " << options_.threads << " worker threads, "
            << renders_.lanes() << " render lanes\n"
            << "listening on http://127.0.0.1:" << transport_->port() << "/ (WebSocket "
            << "catgs.v1 at ws://127.0.0.1:" << transport_->port() << "/ws)" << std::endl;
}

void Server::wait_for_signal() {
  signals_->async_wait([](const boost::system::error_code&, int sig) {
    std::cout << "signal " << sig << ": shutting down" << std::endl;
  });
  signal_io_.run();
}

void Server::shut_down() {
  manager_->shutdown(1500);  // sessions get ERROR_SHUTTING_DOWN while lws still runs
  transport_->stop();        // destroys the lws context; remaining connections close
  // Sessions are closed, so the pools run dry. Renders first: a render in progress posts its
  // result to its session's strand on io_, which must still be running to take it.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  renders_.drain(deadline);
  drain_workers(deadline);
  stop_pools();
  run_leftovers();
}

void Server::drain_workers(Deadline deadline) {
  work_.reset();
  while (!io_.stopped() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
}

void Server::stop_pools() {
  io_.stop();
  renders_.stop();
  for (auto& t : workers_) t.join();
  workers_.clear();
}

void Server::run_leftovers() {
  // Handlers left behind (past the deadline) hold sessions, whose destructors use shared_: run
  // them now, while it lives, instead of letting the io_contexts destroy them later.
  io_.restart();
  for (int i = 0; i < 10000 && io_.poll() + renders_.poll() > 0; ++i) {}
}

void Server::print_totals() const {
  std::cout << "stopped: " << metrics_.sessions_total.load() << " sessions, " << metrics_.frames_total.load()
            << " frames, " << metrics_.bytes_total.load() << " bytes" << std::endl;
}

}  // namespace catgs::server
