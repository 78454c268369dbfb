// Process-wide counters for /metrics (Prometheus text format). Lock-free; any thread.
#pragma once

#include <atomic>
#include <cstdint>
#include <sstream>
#include <string>

namespace catgs::server {

struct ServerMetrics {
  std::atomic<std::int64_t> connections_open{0};  // WebSocket connections now
  std::atomic<std::int64_t> sessions_open{0};     // connections past a valid Hello, now
  std::atomic<std::uint64_t> sessions_total{0};
  std::atomic<std::uint64_t> frames_total{0};     // frames handed to the transport
  std::atomic<std::uint64_t> key_frames_total{0};
  std::atomic<std::uint64_t> bytes_total{0};      // Frame payload bytes
  std::atomic<std::uint64_t> poses_total{0};
  std::atomic<std::uint64_t> poses_skipped_total{0};
  std::atomic<std::uint64_t> session_errors_total{0};  // sessions ended with an Error

  // The Prometheus exposition text.
  std::string prometheus_text() const {
    std::ostringstream o;
    auto put = [&o](const char* name, const char* type, const char* help, auto value) {
      o << "# HELP " << name << ' ' << help << "\n# TYPE " << name << ' ' << type << '\n'
        << name << ' ' << value << '\n';
    };
    put("catgs_connections", "gauge", "Open WebSocket connections.", connections_open.load());
    put("catgs_sessions", "gauge", "Open sessions (after Hello).", sessions_open.load());
    put("catgs_sessions_total", "counter", "Sessions opened.", sessions_total.load());
    put("catgs_frames_total", "counter", "Frames sent.", frames_total.load());
    put("catgs_key_frames_total", "counter", "IDR frames sent.", key_frames_total.load());
    put("catgs_frame_bytes_total", "counter", "Encoded frame bytes sent.", bytes_total.load());
    put("catgs_poses_total", "counter", "Poses received.", poses_total.load());
    put("catgs_poses_skipped_total", "counter", "Poses replaced before rendering.",
        poses_skipped_total.load());
    put("catgs_session_errors_total", "counter", "Sessions ended with an Error.",
        session_errors_total.load());
    return o.str();
  }
};

}  // namespace catgs::server
