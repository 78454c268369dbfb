#include "good_client.h"

#include <algorithm>
#include <stdexcept>
#include <vector>

#include "camera/trace.h"
#include "loadgen/video_decoder.h"
#include "stream_checks.h"

namespace catgs::itest {

using loadgen::pose_from_camera;

GoodClient::GoodClient(int port, int width, int height) : width_(width), height_(height) {
  client_.connect(port);
  client_.hello(width, height);
  thread_ = std::thread([this] { run(); });
}

void GoodClient::stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

double GoodClient::max_gap_ms() {
  std::lock_guard<std::mutex> lock(mutex_);
  return std::max(max_gap_ms_, std::chrono::duration<double, std::milli>(Clock::now() - last_frame_).count());
}

void GoodClient::reset_gaps() {
  std::lock_guard<std::mutex> lock(mutex_);
  max_gap_ms_ = 0;
  last_frame_ = Clock::now();
}

std::string GoodClient::error() {
  std::lock_guard<std::mutex> lock(mutex_);
  return error_;
}

std::optional<loadgen::pb::Error> GoodClient::server_error() {
  std::lock_guard<std::mutex> lock(mutex_);
  return server_error_;
}

bool GoodClient::wait_frames(int n, int timeout_ms) {
  const int target = frames() + n;
  const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  while (Clock::now() < deadline) {
    if (frames() >= target) return true;
    if (!error().empty()) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

bool GoodClient::wait_end(int timeout_ms) {
  const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  while (Clock::now() < deadline && !ended_) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  return ended_;
}

GoodClient::Clock::time_point GoodClient::last_frame_at() {
  std::lock_guard<std::mutex> lock(mutex_);
  return last_frame_;
}

GoodClient::Clock::time_point GoodClient::ended_at() {
  std::lock_guard<std::mutex> lock(mutex_);
  return ended_at_;
}

void GoodClient::run() {
  try {
    const Trace orbit = biker_orbit(width_, height_, 24);
    loadgen::VideoDecoder dec;
    std::vector<std::uint8_t> rgba;
    std::uint32_t seq = 0;
    bool outstanding = false;
    while (!stop_) {
      if (!outstanding) {
        client_.send_pose(pose_from_camera(orbit[seq % orbit.size()].camera, seq, now_ms()));
        seq++;
        outstanding = true;
      }
      auto m = client_.recv(50);
      if (!m) continue;
      if (m->has_error()) {
        {
          std::lock_guard<std::mutex> lock(mutex_);
          server_error_ = m->error();
        }
        throw std::runtime_error("good client got Error: " + m->error().reason());
      }
      if (m->has_stats() && m->stats().drain_ms_left() > 0) drain_ms_left_ = m->stats().drain_ms_left();
      if (!m->has_frame()) continue;
      int w = 0, h = 0;
      if (!dec.decode(m->frame().payload(), rgba, w, h) || w != width_ || h != height_)
        throw std::runtime_error("good client: frame did not decode to the viewport size");
      if (m->frame().pose_sequence() + 1 == seq) outstanding = false;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        const auto now = Clock::now();
        max_gap_ms_ = std::max(max_gap_ms_, std::chrono::duration<double, std::milli>(now - last_frame_).count());
        last_frame_ = now;
      }
      frames_++;
    }
    client_.ws().close();
  } catch (const std::exception& e) {
    std::lock_guard<std::mutex> lock(mutex_);
    error_ = e.what();
    ended_at_ = Clock::now();
    ended_ = true;
  }
}

}  // namespace catgs::itest
