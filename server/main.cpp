// catgs-server: the CaT-GS Stream remote-rendering server (DESIGN.md "Server").
#include <utility>  // Boost 1.74 Asio under C++20 needs std::exchange declared first

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>

#include <chrono>
#include <csignal>
#include <iostream>
#include <thread>
#include <vector>

extern "C" {
#include <libavutil/log.h>
}

#include "scene/ply_io.h"
#include "renderer/renderer.h"
#include "encode/encoder.h"
#include "session/initial_pose.h"
#include "server_options.h"
#include "session/session_manager.h"
#include "transport/transport.h"

using namespace catgs;
using namespace catgs::server;

int main(int argc, char** argv) {
  ServerOptions options;
  try {
    if (!parse_server_options(argc, argv, options)) return 0;
  } catch (const std::exception& e) {
    std::cerr << "catgs-server: " << e.what() << "\n";
    return 2;
  }
  av_log_set_level(AV_LOG_ERROR);  // x264 prints a banner per encoder otherwise
  try {
    const auto t0 = std::chrono::steady_clock::now();
    auto model = std::make_shared<const GaussianModel>(load_scene(options.scene));
    const double load_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    std::cout << "scene: " << options.scene << " (" << model->name << "), " << model->size()
              << " Gaussians, SH degree " << model->sh_degree << ", loaded in " << load_ms
              << " ms\n";

    RenderOptions render_options;
    render_options.pipeline = parse_pipeline(options.pipeline);
    // Resolve "auto" once so every session uses the same core, and log why.
    std::string why;
    const std::string renderer_kind =
        make_renderer(options.renderer, model, render_options, &why)->name();
    std::cout << "renderer: " << renderer_kind << " (" << why << "), pipeline "
              << pipeline_name(render_options.pipeline) << "\n";
    // Resolve the encoder once too (an encoder at a small size; "auto" probes NVENC here, once
    // per process). Sessions ask for options.encoder again and get the same verdict.
    ServerMetrics metrics;
    EncoderConfig probe;
    probe.width = 256;
    probe.height = 256;
    std::string enc_why;
    bool fell_back = false;
    const std::string encoder_kind =
        make_encoder(options.encoder, probe, &enc_why, &fell_back)->name();
    if (fell_back) metrics.encoder_fallbacks_total++;
    std::cout << "encoder: " << encoder_kind << " (" << enc_why << "), crf " << options.crf << "\n";
    metrics.renderer = renderer_kind;
    metrics.encoder = encoder_kind;
    metrics.pipeline = pipeline_name(render_options.pipeline);

    boost::asio::io_context io, render_io;
    const int render_lanes =
        options.render_lanes > 0 ? options.render_lanes : (renderer_kind == "cuda" ? 4 : options.threads);
    TransportOptions topts;
    topts.bind = options.bind;
    topts.port = options.port;
    topts.web_root = options.web_root;
    topts.socket_send_buffer = options.socket_send_buffer;
    // The manager and the transport refer to each other: the manager is built on a SessionShared
    // that names the transport, which is created right after with the manager as its handler.
    std::unique_ptr<Transport> transport;
    std::unique_ptr<SessionShared> shared;
    std::unique_ptr<SessionManager> manager;
    struct Forward final : TransportHandler {
      SessionManager* m = nullptr;
      void on_open(ConnId id) override { m->on_open(id); }
      void on_message(ConnId id, MessageKind k, std::string b) override {
        m->on_message(id, k, std::move(b));
      }
      void on_sent(ConnId id) override { m->on_sent(id); }
      void on_close(ConnId id) override { m->on_close(id); }
      std::string metrics_text() override { return m->metrics_text(); }
    } forward;
    transport = std::make_unique<Transport>(topts, forward);
    shared = std::unique_ptr<SessionShared>(new SessionShared{
        io, render_io, *transport, metrics, options, model, model->bounds(), first_view_bounds(*model),
        render_options, renderer_kind, encoder_kind});
    manager = std::make_unique<SessionManager>(*shared);
    forward.m = manager.get();

    // SIGINT/SIGTERM are caught from here on (one that arrives before the wait below is kept),
    // on a dedicated io_context so the pool keeps serving meanwhile. Registered before the
    // "listening" line: a supervisor that stops the server right after it gets a clean shutdown.
    boost::asio::io_context signal_io;
    boost::asio::signal_set signals(signal_io, SIGINT, SIGTERM);
    // Listen first: a busy port then fails before any thread exists. Work posted before the
    // pool starts just waits in the io_context.
    transport->start();
    auto work = boost::asio::make_work_guard(io);
    std::vector<std::thread> pool;
    for (int i = 0; i < options.threads; ++i) pool.emplace_back([&io] { io.run(); });
    auto render_work = boost::asio::make_work_guard(render_io);
    for (int i = 0; i < render_lanes; ++i) pool.emplace_back([&render_io] { render_io.run(); });
    std::cout << "web root: " << options.web_root << "\n"
              << "sessions: at most " << options.max_sessions << ", " << options.threads
              << " worker threads, " << render_lanes << " render lanes\n"
              << "listening on http://127.0.0.1:" << transport->port() << "/ (WebSocket "
              << "catgs.v1 at ws://127.0.0.1:" << transport->port() << "/ws)" << std::endl;

    signals.async_wait([](const boost::system::error_code&, int sig) {
      std::cout << "signal " << sig << ": shutting down" << std::endl;
    });
    signal_io.run();

    manager->shutdown(1500);  // sessions get ERROR_SHUTTING_DOWN while lws still runs
    transport->stop();        // destroys the lws context; remaining connections close
    // Sessions are closed, so the pools run dry. Renders first: a render in progress posts its
    // result to its session's strand on `io`, which must still be running to take it.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(3);
    render_work.reset();
    while (!render_io.stopped() && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    work.reset();
    while (!io.stopped() && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    io.stop();
    render_io.stop();
    for (auto& t : pool) t.join();
    // Handlers left behind (past the deadline) hold sessions, whose destructors use `shared`:
    // run them now, while it lives, instead of letting the io_contexts destroy them later.
    io.restart();
    render_io.restart();
    for (int i = 0; i < 10000 && io.poll() + render_io.poll() > 0; ++i) {
    }
    std::cout << "stopped: " << metrics.sessions_total.load() << " sessions, "
              << metrics.frames_total.load() << " frames, " << metrics.bytes_total.load()
              << " bytes" << std::endl;
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "catgs-server: " << e.what() << "\n";
    return 1;
  }
}
