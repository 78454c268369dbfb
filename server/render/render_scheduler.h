// The render scheduler: the FIFO of render lanes every session's renders share (DESIGN.md
// "Server").
//
// Sessions post their render jobs here; a fixed number of "render lanes" (threads) take them
// first come first served. A FIFO rather than the worker pool: sessions take turns on the GPU in
// arrival order, so a session whose frames need more host syncs (catgs key frames) cannot starve
// the others, and a render waiting for its turn holds no worker thread (strands, encodes and
// timers keep running on the pool meanwhile).
//
// Lane count (default_lanes): --render-lanes when given; otherwise 4 with the CUDA renderer (a
// few renders in flight share one GPU) and --threads with the CPU renderer (a CPU render is CPU
// work like the pool's, so it gets as many threads).
//
// Threads: post() is thread-safe (sessions post from their strands). start(), drain(), stop() and
// poll() belong to the thread that owns the server (start-up and shutdown), in that order.
#pragma once

#include <utility>  // Boost 1.74 Asio under C++20 needs std::exchange declared first

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>

#include <chrono>
#include <cstddef>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace catgs::server {

class RenderScheduler {
 public:
  RenderScheduler() = default;
  // Stops and joins lanes still running (a server that never reached its orderly shutdown); jobs
  // still queued are destroyed without running.
  ~RenderScheduler();
  RenderScheduler(const RenderScheduler&) = delete;
  RenderScheduler& operator=(const RenderScheduler&) = delete;

  // The lane count for `requested` (ServerOptions::render_lanes; > 0 wins), the resolved
  // `renderer_kind` ("cpu" or "cuda") and the worker count `threads`.
  static int default_lanes(int requested, const std::string& renderer_kind, int threads);

  // Starts `lanes` (>= 1) lane threads. Jobs posted before start() wait in the FIFO.
  void start(int lanes);
  // Lanes started.
  int lanes() const { return static_cast<int>(lanes_.size()); }

  // Thread-safe. Queues `job` (a void() callable) behind every job posted before it; a lane runs
  // it. A job must not throw (an exception would end its lane's thread and the process).
  template <class Job>
  void post(Job&& job) {
    boost::asio::post(io_, std::forward<Job>(job));
  }

  // Shutdown, step 1: no more work is expected (sessions are closed); waits until the lanes
  // have run every queued job or `deadline` passes. Returns true when the FIFO ran dry.
  bool drain(std::chrono::steady_clock::time_point deadline);
  // Step 2: stops the lanes (a job in progress finishes; queued ones stay queued) and joins them.
  void stop();
  // Step 3, after stop(): runs the jobs left queued (past drain's deadline) on the calling
  // thread, without waiting for more. Returns how many ran.
  std::size_t poll();

 private:
  boost::asio::io_context io_;
  std::optional<boost::asio::executor_work_guard<boost::asio::io_context::executor_type>> work_;
  std::vector<std::thread> lanes_;
};

}  // namespace catgs::server
