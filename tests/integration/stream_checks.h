// Helpers shared by the integration tests: server flags, the bundled scene and its orbit, waiting
// for a message, and the image check (a decoded frame vs the CPU render of its pose).
#pragma once

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cpu/cpu_renderer.h"
#include "scene/gaussian_model.h"
#include "camera/trace.h"
#include "loadgen/video_decoder.h"
#include "loadgen/stream_client.h"

namespace catgs::itest {

namespace pb = ::catgs::stream::v1;

inline const std::string kBiker = std::string(CATGS_ASSETS_DIR) + "/scenes/biker.compressed.ply";
inline const std::string kDataDir = CATGS_DATA_DIR;

// Server flags shared by the tests: CPU renderer, exact pipeline, a short slow-client timeout, a
// 3 s drain, then `extra` (later flags win).
std::vector<std::string> server_args(const std::string& scene, std::vector<std::string> extra = {});

// The scene at `path`, loaded once per test process.
std::shared_ptr<const GaussianModel> load_model(const std::string& path);

// An orbit of `frames` poses at 10 Hz around the biker's bounds at a distance that shows it whole.
Trace biker_orbit(int width, int height, int frames);

// Steady clock, ms (the client clock of poses).
double now_ms();

// Waits for the next message satisfying `want`, skipping others; nullopt on timeout.
template <class Pred>
std::optional<pb::ServerMessage> wait_for(loadgen::StreamClient& c, int timeout_ms, Pred want) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline) {
    auto m = c.recv(50);
    if (m && want(*m)) return m;
  }
  return std::nullopt;
}

// One connect / Hello (96 x 64) / pose / disconnect cycle against the server on `port`, the pose
// orbit[i % size]: for even i it waits for the frame, and it closes cleanly for i % 4 < 2 and
// drops the connection (a reset, mid-render for odd i) otherwise.
void connect_and_leave(int port, int i, const Trace& orbit);

// Reads until the server sends Error (returned) or closes; nullopt if neither in time.
std::optional<pb::Error> expect_error(loadgen::StreamClient& c, int timeout_ms = 10000);

// True when the server closes the connection within timeout_ms.
bool expect_closed(loadgen::StreamClient& c, int timeout_ms = 5000);

// PSNR (dB) of frame `f` decoded by `dec` against `ref`'s render of `pose`; -1 when the decoder
// gave no picture. Adds a failure when the decoded size differs from the Frame's.
double frame_psnr(loadgen::VideoDecoder& dec, cpu::CpuRenderer& ref, const pb::Frame& f, const pb::Pose& pose);

// Value of the first sample of `series` (e.g. `catgs_sessions` or `x{kind="sub"}`) in the
// Prometheus text `metrics`; -1 when absent.
double metric_value(const std::string& metrics, const std::string& series);

}  // namespace catgs::itest
