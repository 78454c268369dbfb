// catgs-loadgen: a headless client that streams an orbit from a running catgs-server and reports
// pose-to-frame latency and frame rate. It reports; it does not pass or fail on time.
//
//   catgs-loadgen --port 8080 --width 1280 --height 720 --seconds 10 --rate 0
//   --rate 0: closed loop (the next pose is sent when a frame arrives, keeping --depth poses
//   outstanding); --rate R: poses at R Hz regardless of frames (latest wins on the server).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <stdexcept>
#include <string>
#include <vector>

#include "catgs/trace.h"
#include "h264_decoder.h"
#include "stream_client.h"

using namespace catgs;
using namespace catgs::loadgen;
using Clock = std::chrono::steady_clock;

namespace {

double now_ms() {
  return std::chrono::duration<double, std::milli>(Clock::now().time_since_epoch()).count();
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const auto i = static_cast<std::size_t>(p / 100.0 * static_cast<double>(v.size() - 1) + 0.5);
  return v[std::min(i, v.size() - 1)];
}

}  // namespace

int main(int argc, char** argv) {
  int port = 8080, width = 1280, height = 720, depth = 1;
  double seconds = 10, rate = 0;
  bool decode = false;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      auto next = [&]() -> std::string {
        if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
        return argv[++i];
      };
      if (a == "--port") port = std::stoi(next());
      else if (a == "--width") width = std::stoi(next());
      else if (a == "--height") height = std::stoi(next());
      else if (a == "--seconds") seconds = std::stod(next());
      else if (a == "--rate") rate = std::stod(next());
      else if (a == "--depth") depth = std::max(1, std::stoi(next()));
      else if (a == "--decode") decode = next() == "1";
      else throw std::invalid_argument("unknown option " + a);
    }
  } catch (const std::exception& e) {
    std::cerr << "catgs-loadgen: " << e.what()
              << "\nusage: catgs-loadgen --port N --width W --height H --seconds S --rate R "
                 "--depth D --decode 0|1\n";
    return 2;
  }
  try {
    StreamClient client;
    client.connect(port);
    const pb::Welcome welcome = client.hello(width, height);
    width = static_cast<int>(welcome.width());
    height = static_cast<int>(welcome.height());
    Bounds b;
    b.min = {welcome.scene_bounds().min().x(), welcome.scene_bounds().min().y(),
             welcome.scene_bounds().min().z()};
    b.max = {welcome.scene_bounds().max().x(), welcome.scene_bounds().max().y(),
             welcome.scene_bounds().max().z()};
    // An orbit at the distance of the server's initial pose.
    const auto& ip = welcome.initial_pose().position();
    const glm::vec3 start(static_cast<float>(ip.x()), static_cast<float>(ip.y()),
                          static_cast<float>(ip.z()));
    const float radius = glm::length(start - b.center());
    GeneratorParams gp;
    gp.duration_s = 10.0;
    gp.rate_hz = 60.0;
    gp.width = width;
    gp.height = height;
    gp.fov_deg = 60.0f;
    const Trace orbit = make_orbit(b, radius, 0.3f * radius, 360.0f, gp);

    H264Decoder decoder;
    std::vector<std::uint8_t> rgba;
    std::vector<double> latency, render, encode, server_total;
    std::uint32_t seq = 0;
    std::size_t frames = 0, bytes = 0, key_frames = 0;
    int outstanding = 0;
    auto send_next = [&] {
      const Camera& cam = orbit[seq % orbit.size()].camera;
      client.send_pose(pose_from_camera(cam, seq++, now_ms()));
    };
    const auto t0 = Clock::now();
    const auto end = t0 + std::chrono::duration<double>(seconds);
    auto next_pose_at = t0;
    const auto period = std::chrono::duration<double>(rate > 0 ? 1.0 / rate : 0.0);
    Clock::time_point first_frame{}, last_frame{};
    while (Clock::now() < end) {
      if (rate > 0) {
        while (Clock::now() >= next_pose_at) {
          send_next();
          next_pose_at += std::chrono::duration_cast<Clock::duration>(period);
        }
      } else {
        while (outstanding < depth) {
          send_next();
          outstanding++;
        }
      }
      int wait = 50;
      if (rate > 0)
        wait = std::max(0, static_cast<int>(std::chrono::duration_cast<std::chrono::milliseconds>(
                                                next_pose_at - Clock::now()).count()));
      auto msg = client.recv(wait);
      if (!msg) continue;
      if (msg->has_error()) {
        std::cerr << "server error: " << msg->error().reason() << "\n";
        return 1;
      }
      if (!msg->has_frame()) continue;
      const pb::Frame& f = msg->frame();
      const double lat = now_ms() - f.client_time_ms();
      if (frames == 0) first_frame = Clock::now();
      last_frame = Clock::now();
      frames++;
      if (outstanding > 0) outstanding--;
      bytes += f.payload().size();
      if (f.key_frame()) key_frames++;
      if (decode) {
        int w = 0, h = 0;
        decoder.decode(f.payload(), rgba, w, h);
      }
      if (frames > 5) {  // skip warm-up (first IDR, encoder start)
        latency.push_back(lat);
        render.push_back(f.timings().render_ms());
        encode.push_back(f.timings().convert_ms() + f.timings().encode_ms());
        server_total.push_back(f.timings().total_ms());
      }
    }
    const double span = std::chrono::duration<double>(last_frame - first_frame).count();
    std::printf("session %s scene %s %dx%d renderer %s encoder %s pipeline %s\n",
                welcome.session_id().c_str(), welcome.scene_name().c_str(), width, height,
                welcome.renderer().c_str(), welcome.encoder().c_str(), welcome.pipeline().c_str());
    std::printf("mode: %s\n", rate > 0 ? ("paced " + std::to_string(rate) + " Hz").c_str()
                                       : ("closed loop, depth " + std::to_string(depth)).c_str());
    std::printf("frames %zu (key %zu) in %.2f s: %.2f FPS, %.1f kB/frame\n", frames, key_frames,
                span, frames > 1 ? static_cast<double>(frames - 1) / span : 0.0,
                frames ? static_cast<double>(bytes) / static_cast<double>(frames) / 1000.0 : 0.0);
    std::printf("pose->frame latency ms: p50 %.1f  p95 %.1f  max %.1f\n", percentile(latency, 50),
                percentile(latency, 95), percentile(latency, 100));
    std::printf("server ms: render p50 %.1f, convert+encode p50 %.1f, pose->sent p50 %.1f\n",
                percentile(render, 50), percentile(encode, 50), percentile(server_total, 50));
    client.ws().close();
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "catgs-loadgen: " << e.what() << "\n";
    return 1;
  }
}
