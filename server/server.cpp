#include "speculation/settings.h"
#include "server.h"

#include <unistd.h>

#include <csignal>
#include <iostream>

#include "encode/encoder.h"
#include "proto/message_validation.h"
#include "process/first_view.h"
#include "process/thread_name.h"
#include "process/scene_with_lod.h"
#include "renderer/device_memory.h"
#include "session/video_export.h"
#include "scene/scene_cache.h"

namespace catgs::server {

namespace {

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// A connection while the first scene loads is asked back this soon (issue 91): a load takes about
// a second (RESULTS.md "Scene loading"), and the full server's 2-4 s hint held a page's first
// frame seconds past it; an attempt costs the server one refused handshake.
constexpr std::uint32_t kStartingRetryMs = 300;

}  // namespace

// Connections opened while loading are refused here and never reach the manager: their later
// callbacks find no session (SessionManager ignores unknown ids).
void Server::ToManager::on_open(ConnId id) {
  if (auto* m = manager.load()) return m->on_open(id);
  pb::ServerMessage refusal;
  refusal.mutable_error()->set_code(pb::ERROR_SERVER_FULL);
  refusal.mutable_error()->set_reason("server starting: the scene is loading");
  refusal.mutable_error()->set_retry_after_ms(kStartingRetryMs);
  std::string bytes;
  refusal.SerializeToString(&bytes);
  transport->close(id, std::move(bytes), /*drop_queued=*/true);
}
void Server::ToManager::on_message(ConnId id, MessageKind kind, std::string bytes) {
  if (auto* m = manager.load()) m->on_message(id, kind, std::move(bytes));
}
void Server::ToManager::on_sent(ConnId id, const SocketSample& socket) {
  if (auto* m = manager.load()) m->on_sent(id, socket);
}
void Server::ToManager::on_close(ConnId id) {
  if (auto* m = manager.load()) m->on_close(id);
}
std::string Server::ToManager::metrics_text() {
  if (auto* m = manager.load()) return m->metrics_text();
  // Loading: catgs_info's labels are still being written on the main thread. An empty
  // exposition is valid; the manager's release store publishes them once they are set.
  return "";
}
int Server::ToManager::metrics_access(const std::string& authorization) {
  if (auto* m = manager.load()) return m->metrics_access(authorization);
  return metrics_access_status(options->session.tokens, authorization, *metrics);
}
void Server::ToManager::on_refused(Refusal why, const std::string& peer, const std::string& detail) {
  count_refusal(*metrics, why, peer, detail);
}
std::string Server::ToManager::scenes_json() {
  if (auto* m = manager.load()) return m->scenes_json();
  return "[]\n";
}
int Server::ToManager::readiness(std::string& body) {
  if (auto* m = manager.load()) return m->readiness(body);
  body = "loading\n";
  return 503;
}

Server::Server(const ServerOptions& options) : options_(options) {
  transport_ = std::make_unique<Transport>(options_.transport, to_manager_);
  to_manager_.transport = transport_.get();
  to_manager_.options = &options_;
  to_manager_.metrics = &metrics_;
}

// After a normal run() there is nothing left to stop; this is for a run() that threw. The
// transport goes first: its service thread calls into the manager, destroyed before it.
Server::~Server() {
  if (transport_) transport_->stop();
  stop_pools();
}

int Server::run() {
  catch_signals();
  // Listen first: a busy port then fails before any thread exists, and probes get answers
  // (/healthz 200, /readyz 503) while a large scene loads. Work posted before the pools start
  // just waits in their io_contexts.
  transport_->start();
  print_tls();
  std::cout << "probes on " << url_scheme("http") << "://127.0.0.1:" << transport_->port()
            << "/ (/healthz, /readyz: loading)" << std::endl;
  resolve_renderer();
  load_model();
  resolve_encoder();
  build_sessions();
  start_pools();
  to_manager_.manager = manager_.get();  // sessions are admitted from here on (/readyz 200)
  print_listening();
  if (wait_for_signal() == SIGTERM) drain();
  shut_down();
  print_totals();
  return 0;
}

void Server::load_model() {
  SceneStore::Options o;
  o.budget_bytes = static_cast<std::uint64_t>(options_.store.scene_memory_mb) << 20;
  o.metrics = &metrics_;
  o.log = &std::cout;
  const SceneCacheMode mode = options_.store.scene_cache == "write"  ? SceneCacheMode::write
                              : options_.store.scene_cache == "read" ? SceneCacheMode::read
                                                                     : SceneCacheMode::off;
  // The scene with its level of detail (process/scene_with_lod.h): the LOD file beside it, or
  // built (and written, --lod write) when that is missing or stale.
  SceneWithLodOptions lod;
  lod.cache = mode;
  lod.lod = parse_lod_mode(options_.store.lod);
  lod.min_gaussians = options_.store.lod_min_gaussians;
  lod.cache_dir = options_.store.cache_dir == "beside" ? std::string()
                  : options_.store.cache_dir.empty()   ? default_cache_folder()
                                                       : options_.store.cache_dir;
  std::cout << "derived files (scene caches, LOD files): "
            << (lod.cache_dir.empty() ? std::string("beside each scene") : lod.cache_dir) << std::endl;
  lod.log = [](const std::string& line) { std::cout << line << std::endl; };
  lod.metrics = &metrics_;
  o.loader = [lod](const std::string& path, const LoadProgress& progress) {
    return load_scene_with_lod(path, lod, progress);
  };
  // One copy of each loaded scene per GPU, uploaded before its first session and dropped with it.
  o.prepare = [this](LoadedScene& scene) {
    // The CPU renderer's allowance counts the copy a GPU would hold (renderer/device_memory.h).
    if (gpus_->devices().empty())
      scene.device_memory_holds.push_back(gpus_->add_scene(-1, scene_device_bytes(*scene.model)));
    for (int d : gpus_->devices()) {
      const auto t0 = std::chrono::steady_clock::now();
      const std::size_t before = cuda_device_memory_used(d);
      scene.residents.push_back(make_renderer("cuda", scene.model, render_options_, nullptr, d));
      // The device copy's size (issue 46: what a scene costs the GPU before any session).
      const std::size_t after = cuda_device_memory_used(d);
      const double mib = static_cast<double>(after - std::min(before, after)) / (1024.0 * 1024.0);
      // The accounting holds what the copy took (a resident renderer's first buffers included),
      // or the copy's own size where another process allocated meanwhile.
      scene.device_memory_holds.push_back(gpus_->add_scene(
          d, std::max<std::uint64_t>(scene_device_bytes(*scene.model), after - std::min(before, after))));
      std::cout << "gpu " << d << ": scene " << scene.model->name << " uploaded in " << ms_since(t0) << " ms, "
                << static_cast<long>(mib) << " MiB of device memory (with its LOD levels, " << scene.model->lod.size()
                << " chunks; " << cuda_upload_report(*scene.residents.back()) << ")" << std::endl;
    }
  };
  std::vector<SceneStore::Source> sources{{options_.store.scene, options_.store.cameras}};
  for (const std::string& file : options_.store.more_scenes)
    sources.push_back({file, ""});  // cameras found beside them
  scenes_ = std::make_unique<SceneStore>(std::move(sources), std::move(o));
  // The default scene now, so that its first session starts at once and a bad file or --cameras
  // stops the start; the others on first use (process/scene_store.h).
  scenes_->load_now(0);
  if (scenes_->size() > 1)
    std::cout << "scenes: " << scenes_->names() << " (the first loaded; the others load on first use"
              << (options_.store.scene_memory_mb
                      ? ", within --scene-memory-mb " + std::to_string(options_.store.scene_memory_mb)
                      : std::string())
              << ")" << std::endl;
}

void Server::resolve_renderer() {
  render_options_.pipeline = parse_pipeline(options_.render.pipeline);
  // A session's list buffers are bounded (issue 61): a longer list is drawn in passes.
  render_options_.list_budget.max_bytes = static_cast<std::uint64_t>(options_.render.list_memory_mb) << 20;
  render_options_.lod_error_px = options_.session.frame.lod.bound_px;
  render_options_.occlusion_culling = options_.render.occlusion_cull;
  render_options_.depth_grid_cell = options_.render.depth_grid_px;
  // A session's catgs windows open only where its own measured frame costs say they repay
  // (SpeculationParams::cost_model; --speculation cost=off for the paper's rule alone).
  render_options_.speculation.cost_model = true;
  apply_speculation_settings(render_options_.speculation, options_.render.speculation);
  // Resolved once, before any scene loads, so every session uses the same core and the log says
  // why: over a one-Gaussian model (the choice does not depend on the scene).
  // Before any CUDA context exists: lanes waiting on a spinning core would take it from the
  // encoders (docs/history/sessions_per_host.md, "Lanes that block while they wait for the GPU").
  if (options_.render.renderer != "cpu") set_cuda_host_wait(options_.render.gpu_wait);
  auto probe = std::make_shared<GaussianModel>();
  probe->name = "probe";
  probe->resize(1);
  probe->rotations[0] = 1.0f;  // (w, x, y, z) = identity
  std::string why;
  renderer_kind_ = make_renderer(options_.render.renderer, probe, render_options_, &why)->name();
  std::cout << "renderer: " << renderer_kind_ << " (" << why << "), pipeline "
            << pipeline_name(render_options_.pipeline) << "\n";
  resolve_gpus();
}

void Server::resolve_gpus() {
  std::vector<int> devices;
  if (renderer_kind_ == "cuda") devices = parse_gpus(options_.render.gpus, cuda_device_count());
  // Each GPU's capacity: its memory less the reserve, or --device-memory-mb where smaller; the
  // CPU renderer's host slot: the allowance (0: unlimited).
  const std::uint64_t allowance = static_cast<std::uint64_t>(options_.render.device_memory_mb) << 20;
  std::vector<std::uint64_t> capacity;
  for (int d : devices) {
    const std::uint64_t total = cuda_device_memory_total(d);
    const std::uint64_t reserve = static_cast<std::uint64_t>(options_.render.device_memory_reserve_mb) << 20;
    std::uint64_t c = total > reserve ? total - reserve : 1;
    if (allowance > 0) c = std::min(c, allowance);
    capacity.push_back(c);
    std::cout << "gpu " << d << ": " << memory_text(c) << " for scenes and sessions (" << memory_text(total)
              << " in all)" << std::endl;
  }
  if (devices.empty()) capacity.push_back(allowance);
  // What the driver reports free is read at the door (issue 73): another process may hold memory.
  GpuAssignment::FreeMemory free_memory;
  if (!devices.empty()) free_memory = [](int device) { return cuda_device_memory_free(device); };
  gpus_ = std::make_unique<GpuAssignment>(devices, capacity, free_memory,
                                          static_cast<std::uint64_t>(options_.render.device_memory_reserve_mb) << 20);
  metrics_.set_gpus(devices, [g = gpus_.get()] { return g->sessions(); });
  metrics_.device_memory = [g = gpus_.get()] {
    std::vector<ServerMetrics::MemoryRow> rows;
    for (const GpuAssignment::Memory& m : g->memory())
      rows.push_back(
          {m.device >= 0 ? std::to_string(m.device) : "host", m.capacity, m.scenes, m.reserved, m.held, m.driver_free});
    return rows;
  };
}

void Server::resolve_encoder() {
  // An encoder at a small size: "auto" probes NVENC here, once per process. Sessions ask for
  // options.encoder again and get the same verdict.
  EncoderConfig probe;
  probe.width = 256;
  probe.height = 256;
  std::string why;
  bool fell_back = false;
  encoder_kind_ = make_encoder(options_.session.frame.encoder, probe, &why, &fell_back)->name();
  if (fell_back) metrics_.encoder_fallbacks_total++;
  std::cout << "encoder: " << encoder_kind_ << " (" << why << "), crf " << options_.session.frame.encoder_policy.crf
            << ", bitrate "
            << (options_.session.frame.encoder_policy.bitrate_kbps < 0 ? "auto"
                : options_.session.frame.encoder_policy.bitrate_kbps == 0
                    ? "off"
                    : std::to_string(options_.session.frame.encoder_policy.bitrate_kbps))
            << ", " << options_.session.frame.encoder_policy.usable_cores << " cores for encoders, AV1 "
            << options_.session.frame.encoder_policy.av1 << " (speed "
            << options_.session.frame.encoder_policy.av1_speed << ")\n";
  metrics_.renderer = renderer_kind_;
  metrics_.encoder = encoder_kind_;
  metrics_.pipeline = pipeline_name(render_options_.pipeline);
}

void Server::build_sessions() {
  shared_ =
      std::unique_ptr<SessionShared>(new SessionShared{io_, renders_, *gpus_, *transport_, metrics_, options_.session,
                                                       *scenes_, render_options_, renderer_kind_, encoder_kind_});
  manager_ = std::make_unique<SessionManager>(*shared_);
  // /readyz's memory test until the first visitor: a 1280x720 session of the default scene.
  if (const auto first = scenes_->loaded(0))
    shared_->next_session_bytes = first_session_device_bytes(first->model->size(), 1280, 720, render_options_.pipeline,
                                                             render_options_.list_budget);
  // Video export's files: a folder of their own, emptied of what an earlier run left there.
  if (video_export_built() && options_.session.export_limits.max_concurrent > 0) {
    shared_->export_folder = export_folder(options_.export_dir);
    const int stale = remove_stale_exports(shared_->export_folder);
    std::cout << "video export: files in " << shared_->export_folder;
    if (stale) std::cout << " (deleted " << stale << " left by an earlier run)";
    std::cout << std::endl;
  }
}

void Server::catch_signals() {
  // SIGINT/SIGTERM are caught from here on (one that arrives before wait_for_signal() is kept).
  // Registered before the "listening" line: a supervisor that stops the server right after it
  // gets a clean shutdown.
  // SIGHUP reloads the TLS certificate and key (reload_tls) and is caught for the same reason.
  signals_.emplace(signal_io_, SIGINT, SIGTERM, SIGHUP);
}

void Server::arm_signals() {
  last_signal_ = 0;
  signal_io_.restart();
  signals_->async_wait([this](const boost::system::error_code& ec, int sig) {
    if (!ec) last_signal_ = sig;
  });
}

std::string Server::url_scheme(const std::string& plain) const { return transport_->tls() ? plain + "s" : plain; }

void Server::print_tls() const {
  if (!transport_->tls()) return;
  const TlsCredentials& c = transport_->tls_credentials();
  std::cout << "tls: " << options_.transport.tls_cert << " (" << c.describe() << "); HTTPS and WSS only, SIGHUP reloads"
            << std::endl;
}

void Server::reload_tls() {
  if (!transport_->tls()) {
    std::cout << "SIGHUP: nothing to reload (no --tls-cert)" << std::endl;
    return;
  }
  try {
    const TlsCredentials c = transport_->reload_tls();
    std::cout << "tls: reloaded on SIGHUP: " << c.describe() << std::endl;
  } catch (const std::exception& e) {
    std::cerr << "catgs-server: tls: reload on SIGHUP failed, the previous certificate stays: " << e.what()
              << std::endl;
  }
}

void Server::start_pools() {
  work_.emplace(io_.get_executor());
  for (int i = 0; i < options_.threads; ++i)
    workers_.emplace_back([this, i] {
      name_this_thread("catgs-pool" + std::to_string(i));
      io_.run();
    });
  int lanes = RenderScheduler::default_lanes(options_.render.render_lanes, renderer_kind_, options_.threads);
  if (options_.render.render_lanes == 0 && !gpus_->devices().empty())  // the CUDA default is per GPU
    lanes *= static_cast<int>(gpus_->devices().size());
  renders_.set_background_yield(std::chrono::milliseconds(options_.render.export_yield_ms));
  renders_.set_frames_per_lane(
      RenderScheduler::default_frames_per_lane(options_.render.frames_per_lane, renderer_kind_));
  renders_.start(lanes, options_.render.max_pixels_in_flight);
}

void Server::print_listening() const {
  std::cout << "web root: " << options_.transport.web_root << "\n"
            << "sessions: at most " << options_.session.max_sessions << ", " << options_.threads << " worker threads, "
            << renders_.lanes() << " render lanes of " << renders_.frames_per_lane() << " frame(s) in flight"
            << (gpus_->devices().empty() ? std::string() : ", " + std::to_string(gpus_->devices().size()) + " GPU(s)")
            << "\n"
            << "listening on " << url_scheme("http") << "://127.0.0.1:" << transport_->port() << "/ (WebSocket "
            << "catgs.v1 at " << url_scheme("ws") << "://127.0.0.1:" << transport_->port() << "/ws)" << std::endl;
}

int Server::wait_for_signal() {
  for (;;) {
    arm_signals();
    signal_io_.run();
    if (last_signal_ != SIGHUP) break;
    reload_tls();
  }
  const int sig = last_signal_;
  std::cout << "signal " << sig << (sig == SIGTERM ? ": draining" : ": shutting down") << std::endl;
  return sig;
}

void Server::drain() {
  const auto t0 = std::chrono::steady_clock::now();
  const auto deadline = t0 + std::chrono::seconds(options_.drain_timeout_s);
  manager_->start_draining(deadline);
  std::cout << "drain: " << manager_->open_sessions() << " sessions may stream for up to " << options_.drain_timeout_s
            << " s; new sessions are refused, /readyz answers 503" << std::endl;
  // Another signal (SIGINT, or SIGTERM again) ends the drain early; SIGHUP still reloads.
  arm_signals();
  while (manager_->open_sessions() > 0 && std::chrono::steady_clock::now() < deadline) {
    signal_io_.run_for(std::chrono::milliseconds(50));
    if (last_signal_ != SIGHUP) {
      if (last_signal_) break;
      continue;
    }
    reload_tls();
    arm_signals();
  }
  const char* why = last_signal_ ? "signal" : manager_->open_sessions() > 0 ? "timeout" : "no sessions left";
  std::cout << "drain ended (" << why << ") after " << ms_since(t0) << " ms, " << manager_->open_sessions()
            << " sessions left" << std::endl;
}

void Server::shut_down() {
  manager_->shutdown(1500);  // sessions get ERROR_SHUTTING_DOWN while lws still runs
  transport_->stop();        // destroys the lws context; remaining connections close
  scenes_->stop();           // loads still running end now; their waiters' news posts to io_, still running
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
