#include "common/image_io.h"
#include "stream_checks.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <mutex>
#include <sstream>

#include "scene/ply_io.h"

namespace catgs::itest {

std::vector<std::string> server_args(const std::string& scene, std::vector<std::string> extra) {
  // A short drain: a test that ends with a session still open must not wait the default 30 s.
  std::vector<std::string> a = {"--scene", scene, "--renderer", "cpu", "--pipeline", "exact", "--threads", "4",
                                "--slow-client-timeout-ms", "2000", "--drain-timeout-s", "3",
                                // Derived files (LOD files, scene caches) in the tests' own folder,
                                // not the user's cache folder nor beside ../shared's scenes.
                                "--cache-dir", (std::filesystem::temp_directory_path() / "catgs-itest-cache").string(),
                                // A test that sends a pose and waits for its frame reads one frame
                                // a pose; on a slow machine the still view's refine frames (their
                                // own test: StillViewEndsAtTheCrfsPicture) would come between.
                                "--still-refine", "off"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

std::shared_ptr<const GaussianModel> load_model(const std::string& path) {
  static std::mutex m;
  static std::map<std::string, std::shared_ptr<const GaussianModel>> cache;
  std::lock_guard<std::mutex> lock(m);
  auto& slot = cache[path];
  if (!slot) slot = std::make_shared<const GaussianModel>(load_scene(path));
  return slot;
}

Trace biker_orbit(int width, int height, int frames) {
  const Bounds b = load_model(kBiker)->bounds();
  GeneratorParams p;
  p.width = width;
  p.height = height;
  p.rate_hz = 10.0;
  p.duration_s = (frames - 1) / p.rate_hz;
  p.fov_deg = 50.0f;
  const float r = 1.4f * glm::length(b.extent());
  return make_orbit(b, r, 0.2f * r, 120.0f, p);
}

void connect_and_leave(int port, int i, const Trace& orbit) {
  loadgen::StreamClient c;
  c.connect(port);
  c.hello(96, 64);
  c.send_pose(loadgen::pose_from_camera(orbit[static_cast<std::size_t>(i) % orbit.size()].camera, 0, now_ms()));
  if (i % 2 == 0) wait_for(c, 10000, [](const pb::ServerMessage& s) { return s.has_frame(); });
  if (i % 4 < 2)
    c.ws().close();
  else
    c.ws().close_abrupt();
}

double now_ms() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double frame_psnr(loadgen::VideoDecoder& dec, cpu::CpuRenderer& ref, const pb::Frame& f, const pb::Pose& pose) {
  std::vector<std::uint8_t> rgba;
  int w = 0, h = 0;
  if (!dec.decode(f.payload(), rgba, w, h)) return -1;
  EXPECT_EQ(w, static_cast<int>(f.width()));
  EXPECT_EQ(h, static_cast<int>(f.height()));
  Image got;
  got.width = w;
  got.height = h;
  got.rgba8 = std::move(rgba);
  Image want;
  ref.render(loadgen::camera_from_pose(pose, w, h), want);
  return psnr_rgba8(got, want);
}

double metric_value(const std::string& metrics, const std::string& series) {
  std::istringstream in(metrics);
  for (std::string line; std::getline(in, line);)
    if (line.size() > series.size() && line.compare(0, series.size(), series) == 0 && line[series.size()] == ' ')
      return std::stod(line.substr(series.size() + 1));
  return -1;
}

std::optional<pb::Error> expect_error(loadgen::StreamClient& c, int timeout_ms) {
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  while (Clock::now() < deadline) {
    try {
      auto m = c.recv(50);
      if (m && m->has_error()) return m->error();
    } catch (const std::exception&) {
      return std::nullopt;  // closed without an Error
    }
  }
  return std::nullopt;
}

bool expect_closed(loadgen::StreamClient& c, int timeout_ms) {
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  while (Clock::now() < deadline) {
    try {
      c.recv(50);
    } catch (const std::exception&) {
      return true;
    }
  }
  return false;
}

}  // namespace catgs::itest
