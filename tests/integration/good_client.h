// A well-behaved session for the integration tests: streams an orbit of the bundled biker scene in
// the background (one pose outstanding), decodes every frame, and records the frames' times, the
// server's Error that ended it, or any other failure.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "loadgen/stream_client.h"

namespace catgs::itest {

class GoodClient {
 public:
  using Clock = std::chrono::steady_clock;
  // Connects to 127.0.0.1:port and says Hello at width x height (throws what
  // StreamClient::hello throws), then streams on its own thread.
  GoodClient(int port, int width = 160, int height = 120);
  ~GoodClient() { stop(); }
  // Stops streaming and closes the connection.
  void stop();
  int frames() const { return frames_.load(); }
  // Stats.drain_ms_left of the last Stats that had one (0: none did).
  std::uint32_t drain_ms_left() const { return drain_ms_left_.load(); }
  // The longest wait between two frames (or since the last one) since reset_gaps(), ms.
  double max_gap_ms();
  void reset_gaps();
  // What went wrong (an Error from the server, a frame that did not decode, a closed
  // connection); empty while all is well.
  std::string error();
  // The server's Error that ended the session, if one came.
  std::optional<loadgen::pb::Error> server_error();
  // Waits until `n` more frames arrived; false on timeout or failure.
  bool wait_frames(int n, int timeout_ms = 30000);
  // Waits until the session ended by itself (an Error or a close); false on timeout.
  bool wait_end(int timeout_ms);
  Clock::time_point last_frame_at();
  Clock::time_point ended_at();

 private:
  void run();

  int width_, height_;
  loadgen::StreamClient client_;
  std::thread thread_;
  std::atomic<bool> stop_{false}, ended_{false};
  std::atomic<int> frames_{0};
  std::atomic<std::uint32_t> drain_ms_left_{0};
  std::mutex mutex_;
  std::string error_;
  std::optional<loadgen::pb::Error> server_error_;
  Clock::time_point last_frame_ = Clock::now(), ended_at_{};
  double max_gap_ms_ = 0;
};

}  // namespace catgs::itest
