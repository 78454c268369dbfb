#include "render/render_scheduler.h"

namespace catgs::server {

RenderScheduler::~RenderScheduler() {
  if (!lanes_.empty()) stop();
}

int RenderScheduler::default_lanes(int requested, const std::string& renderer_kind, int threads) {
  if (requested > 0) return requested;
  return renderer_kind == "cuda" ? 4 : threads;
}

void RenderScheduler::start(int lanes) {
  // The guard keeps the lanes running while the FIFO is momentarily empty.
  work_.emplace(io_.get_executor());
  for (int i = 0; i < lanes; ++i) lanes_.emplace_back([this] { io_.run(); });
}

bool RenderScheduler::drain(std::chrono::steady_clock::time_point deadline) {
  // Without the guard, run() returns in every lane once the queue is empty: stopped() then
  // says the FIFO ran dry.
  work_.reset();
  while (!io_.stopped() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  return io_.stopped();
}

void RenderScheduler::stop() {
  work_.reset();
  io_.stop();
  for (auto& t : lanes_) t.join();
  lanes_.clear();
  // Ready for poll(): a stopped io_context runs nothing until restarted.
  io_.restart();
}

std::size_t RenderScheduler::poll() { return io_.poll(); }

}  // namespace catgs::server
