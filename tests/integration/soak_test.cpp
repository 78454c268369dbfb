// Issue 22's soak: healthy sessions stream for the whole run while churn (connect, Hello, a pose,
// a clean or abrupt close) and hostile clients (garbage messages, a frame declaring 1 GiB, no
// Hello, a ping flood, an over-long HTTP request line) come and go beside them. Asserts what must
// hold whatever the machine's speed: every healthy session streams to the end without an error
// and never waits 10 s for a frame (issue 22 finding 5 stalled one for 27.8 s), every hostile
// client gets its Error (or its connection closed) and ends, and once everyone has gone the
// server holds the file descriptors it held before (no leaked socket) and its allocator holds what
// it held before, within 4 MiB (catgs_heap_in_use_bytes; a leaked session is about 20 MiB). It
// reports the healthy sessions' frame gaps (the longest wait in each 5 s window), the churn and hostile
// counts, memory and descriptors, as a table and, with CATGS_SOAK_JSON=FILE, as JSON.
//
// Length and load from the environment: CATGS_SOAK_SECONDS (default 30, what CI runs) and
// CATGS_SOAK_SESSIONS (default 16). The 10-minute run: CATGS_SOAK_SECONDS=600
// ./build/cpu/bin/catgs_serial_tests --gtest_filter='Soak.*' (results in RESULTS.md). It runs alone
// under ctest (RUN_SERIAL, tests/integration/CMakeLists.txt): it loads the machine.
#include <gtest/gtest.h>

#include <dirent.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "good_client.h"
#include "loadgen/stream_client.h"
#include "server_process.h"
#include "stream_checks.h"

namespace {

using namespace catgs;
using namespace catgs::loadgen;
using namespace catgs::itest;
using Clock = std::chrono::steady_clock;

double env_number(const char* name, double fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::atof(v) : fallback;
}

// Open file descriptors of process `pid` (entries of /proc/PID/fd), -1 if unreadable.
int fd_count(pid_t pid) {
  DIR* d = opendir(("/proc/" + std::to_string(pid) + "/fd").c_str());
  if (!d) return -1;
  int n = 0;
  while (const dirent* e = readdir(d))
    if (e->d_name[0] != '.') ++n;
  closedir(d);
  return n;
}

// The hostile clients, one kind per attempt in turn. Each returns whether the server answered as
// it must: an Error (any code) and a close, or for the raw HTTP line a closed or refused answer.
enum Hostile { kGarbage, kHugeFrame, kNoHello, kPingFlood, kLongUrl, kHostileKinds };
const char* const kHostileNames[kHostileKinds] = {"garbage message", "1 GiB frame", "no Hello", "ping flood",
                                                  "64 KiB URL"};

bool error_then_close(StreamClient& c, int timeout_ms) {
  return expect_error(c, timeout_ms).has_value() && expect_closed(c, 5000);
}

bool long_url(int port) {
  const int fd = connect_loopback(port);
  if (fd < 0) return false;
  const std::string req = "GET /" + std::string(64 * 1024, 'a') + " HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
  (void)!send(fd, req.data(), req.size(), MSG_NOSIGNAL);
  // The server must answer (a status) or close; it must not keep the socket open.
  bool ended = false;
  const auto deadline = Clock::now() + std::chrono::seconds(15);
  while (!ended && Clock::now() < deadline) {
    pollfd p{fd, POLLIN, 0};
    if (poll(&p, 1, 100) <= 0) continue;
    char buf[4096];
    const ssize_t n = recv(fd, buf, sizeof(buf), 0);
    ended = n <= 0 || std::string(buf, static_cast<std::size_t>(n)).rfind("HTTP/1.", 0) == 0;
  }
  close(fd);
  return ended;
}

bool hostile_attempt(int port, Hostile kind) {
  if (kind == kLongUrl) return long_url(port);
  StreamClient c;
  c.connect(port);
  if (kind == kNoHello) return error_then_close(c, 10000);  // the server's --hello-timeout-ms
  c.hello(64, 64);
  if (kind == kGarbage) {
    c.ws().send_binary(std::string(4, '\xff') + "\x0f garbage, not a ClientMessage");
  } else if (kind == kHugeFrame) {
    std::string frame = {static_cast<char>(0x82), static_cast<char>(0x80 | 127)};
    for (int i = 7; i >= 0; --i) frame.push_back(static_cast<char>(((1ull << 30) >> (8 * i)) & 0xff));
    frame += std::string(4, '\x5a') + std::string(1024, '\x11');
    c.ws().send_raw(frame);
  } else {  // kPingFlood: one past the default ping limit's burst of 20
    // No more than one past: messages that reach the socket after the server closed it make the
    // kernel answer with a reset, which can discard the Error (Hardening.PerSessionRateLimits).
    pb::ClientMessage ping;
    ping.mutable_ping()->set_client_time_ms(now_ms());
    for (int i = 0; i < 21; ++i) c.send(ping);
  }
  return error_then_close(c, 10000);
}

struct Sample {
  double t_s;
  long rss_kib;
  double heap_bytes;  // catgs_heap_in_use_bytes: what the server's allocator holds
  int fds;
};

// The most the server's heap may hold after everyone left over what it held before the run: under
// one session's state (see the check).
constexpr double kHeapKept = 4 * 1024 * 1024;

double percentile_of(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(p / 100.0 * static_cast<double>(v.size() - 1) + 0.5)];
}

TEST(Soak, HealthySessionsKeepStreamingThroughChurnAndHostileClients) {
  const double seconds = env_number("CATGS_SOAK_SECONDS", 30);
  const int sessions = static_cast<int>(env_number("CATGS_SOAK_SESSIONS", 16));
  // Room for the healthy sessions, the churn and the hostile ones from one address; no Hello in
  // 2 s ends a connection (the no-Hello client waits for that).
  // Two malloc arenas (inherited), as in DisconnectsMidStreamFreeEverything: fewer arenas to settle.
  setenv("MALLOC_ARENA_MAX", "2", 1);
  ServerProcess server(server_args(kBiker, {"--max-sessions", std::to_string(sessions + 16), "--hello-timeout-ms",
                                            "2000", "--rate-limits", "hello=200/400"}));
  unsetenv("MALLOC_ARENA_MAX");
  const int port = server.port();
  const pid_t pid = server.pid();
  // A warm-up of each kind first: the server makes some things on first use and keeps them (the
  // first session's work queue holds an eventfd, an epoll and a timerfd for good).
  {
    const Trace orbit = biker_orbit(96, 64, 8);
    for (int i = 0; i < 4; ++i) connect_and_leave(port, i, orbit);
    for (int k = 0; k < kHostileKinds; ++k) ASSERT_TRUE(hostile_attempt(port, static_cast<Hostile>(k)));
  }
  std::string metrics;
  auto drained = [&] {  // until the server has noticed every close
    const auto deadline = Clock::now() + std::chrono::seconds(20);
    do {
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
      http_get(port, "/metrics", metrics);
    } while ((metric_value(metrics, "catgs_sessions") != 0 || metric_value(metrics, "catgs_connections") != 0) &&
             Clock::now() < deadline);
  };
  drained();
  const int fds_before = fd_count(pid);
  ASSERT_GT(fds_before, 0);
  const double heap_before = metric_value(metrics, "catgs_heap_in_use_bytes");
  ASSERT_GT(heap_before, 0) << "no catgs_heap_in_use_bytes in /metrics";

  std::vector<std::unique_ptr<GoodClient>> good;
  for (int i = 0; i < sessions; ++i) good.push_back(std::make_unique<GoodClient>(port, 96, 64));
  for (auto& g : good) ASSERT_TRUE(g->wait_frames(1, 60000)) << g->error();
  for (auto& g : good) g->reset_gaps();

  std::atomic<bool> stop{false};
  std::atomic<int> churn_cycles{0}, churn_failures{0};
  std::vector<int> hostile_tries(kHostileKinds, 0), hostile_answered(kHostileKinds, 0);
  std::thread churn([&] {
    const Trace orbit = biker_orbit(96, 64, 8);
    for (int i = 0; !stop; ++i) {
      try {
        connect_and_leave(port, i, orbit);
      } catch (const std::exception&) {
        ++churn_failures;
      }
      ++churn_cycles;
    }
  });
  std::thread hostile([&] {
    for (int i = 0; !stop; ++i) {
      const auto kind = static_cast<Hostile>(i % kHostileKinds);
      bool answered = false;
      try {
        answered = hostile_attempt(port, kind);
      } catch (const std::exception&) {
        answered = false;  // a connect or Hello the server refused counts as unanswered
      }
      ++hostile_tries[kind];
      hostile_answered[kind] += answered ? 1 : 0;
    }
  });

  // Every 5 s: memory, descriptors, and each healthy session's longest wait for a frame.
  const auto t0 = Clock::now();
  std::vector<Sample> samples;
  std::vector<double> window_gaps_ms;
  std::vector<int> frames_at_half(good.size(), 0);
  bool half_taken = false;
  while (std::chrono::duration<double>(Clock::now() - t0).count() < seconds) {
    std::this_thread::sleep_for(std::chrono::seconds(5));
    const double t = std::chrono::duration<double>(Clock::now() - t0).count();
    std::string now;
    http_get(port, "/metrics", now);
    samples.push_back({t, rss_kib(pid), metric_value(now, "catgs_heap_in_use_bytes"), fd_count(pid)});
    for (auto& g : good) {
      window_gaps_ms.push_back(g->max_gap_ms());
      g->reset_gaps();
    }
    if (!half_taken && t >= seconds / 2) {
      for (std::size_t i = 0; i < good.size(); ++i) frames_at_half[i] = good[i]->frames();
      half_taken = true;
    }
  }
  stop = true;
  churn.join();
  hostile.join();

  std::vector<int> frames(good.size());
  for (std::size_t i = 0; i < good.size(); ++i) {
    EXPECT_EQ(good[i]->error(), "") << "healthy session " << i;
    EXPECT_GT(good[i]->frames(), frames_at_half[i]) << "healthy session " << i << " stopped getting frames";
    frames[i] = good[i]->frames();
    good[i]->stop();
  }
  // Everyone has gone: the server's sessions and connections drain, and so do its descriptors.
  drained();
  // Descriptors close a little after the counters say so (the last /metrics request's socket, a
  // WebSocket whose close lws is still finishing), so a snapshot taken at once can be one over the
  // baseline. A leak stays; wait up to 5 s for them to drain.
  int fds_after = fd_count(pid);
  for (const auto until = Clock::now() + std::chrono::seconds(5); fds_after > fds_before && Clock::now() < until;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    fds_after = fd_count(pid);
  }
  // What the allocator holds goes back to where it was before the healthy sessions came (sessions
  // free their state on worker threads a little after the counters drop: wait up to 5 s).
  const auto heap_now = [&] {
    std::string m;
    http_get(port, "/metrics", m);
    return metric_value(m, "catgs_heap_in_use_bytes");
  };
  double heap_after = heap_now();
  for (const auto until = Clock::now() + std::chrono::seconds(5);
       heap_after - heap_before >= kHeapKept && Clock::now() < until;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    heap_after = heap_now();
  }
  EXPECT_LT(heap_after - heap_before, kHeapKept)
      << "the server's heap in use: " << heap_before / (1 << 20) << " MiB before the run, " << heap_after / (1 << 20)
      << " MiB after everyone left: a leak";
  EXPECT_EQ(metric_value(metrics, "catgs_sessions"), 0) << metrics;
  EXPECT_LE(fds_after, fds_before) << "file descriptors " << fds_before << " before, " << fds_after << " after";

  const double max_gap = window_gaps_ms.empty() ? 0 : *std::max_element(window_gaps_ms.begin(), window_gaps_ms.end());
  EXPECT_LT(max_gap, 10000.0) << "a healthy session waited " << max_gap << " ms for a frame";
  EXPECT_GT(churn_cycles.load(), 0);
  EXPECT_EQ(churn_failures.load(), 0) << "churn cycles that failed (refused or broken)";
  for (int k = 0; k < kHostileKinds; ++k)
    EXPECT_EQ(hostile_answered[k], hostile_tries[k]) << kHostileNames[k] << ": not every attempt was answered";
  ASSERT_GE(samples.size(), 2u);
  const Sample& half = samples[(samples.size() - 1) / 2];
  const Sample& last = samples.back();
  // Memory is judged by what the allocator holds after everyone left (above), not by RSS or by the
  // floors within the run, which are reported. RSS keeps the pages an arena grew into: its floors
  // moved -13 to +34 MiB between halves here and +79 MiB in CI (502 -> 581 MiB), issue 75's 64 MiB
  // bound included. Within the run one churn session's state (about 20 MiB at 96x64) comes and
  // goes between samples. After everyone left, the heap came back to 0.4 MiB of where it was
  // before (9.4 -> 9.8 MiB, twice here), and one leaked session would be 20. Flatness over a long
  // run is the 600 s soak's (RESULTS.md, CATGS_SOAK_SECONDS=600).
  const std::size_t mid = samples.size() / 2;
  const auto by_heap = [](const Sample& a, const Sample& b) { return a.heap_bytes < b.heap_bytes; };
  const double heap_first = std::min_element(samples.begin(), samples.begin() + mid, by_heap)->heap_bytes;
  const double heap_second = std::min_element(samples.begin() + mid, samples.end(), by_heap)->heap_bytes;
  const auto by_rss = [](const Sample& a, const Sample& b) { return a.rss_kib < b.rss_kib; };
  const long floor_first = std::min_element(samples.begin(), samples.begin() + mid, by_rss)->rss_kib;
  const long floor_second = std::min_element(samples.begin() + mid, samples.end(), by_rss)->rss_kib;

  // The report.
  int fds_max = 0;
  long rss_max = 0;
  for (const Sample& s : samples) {
    fds_max = std::max(fds_max, s.fds);
    rss_max = std::max(rss_max, s.rss_kib);
  }
  const int frames_min = *std::min_element(frames.begin(), frames.end());
  double frames_sum = 0;
  for (int f : frames) frames_sum += f;
  std::cout << "[ soak ] " << seconds << " s, " << sessions << " healthy sessions at 96x64 (CPU renderer)\n"
            << "[ soak ] frames per healthy session: min " << frames_min << ", mean "
            << frames_sum / static_cast<double>(frames.size()) << "; longest wait for a frame per 5 s window: p50 "
            << percentile_of(window_gaps_ms, 50) << " ms, p99 " << percentile_of(window_gaps_ms, 99) << " ms, max "
            << max_gap << " ms\n"
            << "[ soak ] churn cycles " << churn_cycles << " (" << churn_failures << " failed)\n";
  for (int k = 0; k < kHostileKinds; ++k)
    std::cout << "[ soak ] hostile " << kHostileNames[k] << ": " << hostile_answered[k] << " of " << hostile_tries[k]
              << " answered\n";
  std::cout << "[ soak ] server RSS " << samples.front().rss_kib / 1024 << " MiB at 5 s, " << half.rss_kib / 1024
            << " MiB at half time, " << last.rss_kib / 1024 << " MiB at the end (max " << rss_max / 1024 << ", lowest "
            << floor_first / 1024 << " in the first half, " << floor_second / 1024 << " in the second"
            << "); heap in use: lowest " << heap_first / (1 << 20) << " MiB in the first half, "
            << heap_second / (1 << 20) << " in the second (samples:";
  for (const Sample& smp : samples) std::cout << ' ' << smp.heap_bytes / (1 << 20);
  std::cout << " MiB), " << heap_before / (1 << 20) << " MiB before the run, " << heap_after / (1 << 20)
            << " after; file descriptors " << fds_before << " before, max " << fds_max << ", " << fds_after
            << " after everyone left\n";
  if (const char* path = std::getenv("CATGS_SOAK_JSON")) {
    nlohmann::json j;
    j["seconds"] = seconds;
    j["sessions"] = sessions;
    j["frames"] = frames;
    j["window_max_gap_ms"] = window_gaps_ms;
    j["churn_cycles"] = churn_cycles.load();
    j["churn_failures"] = churn_failures.load();
    for (int k = 0; k < kHostileKinds; ++k)
      j["hostile"][kHostileNames[k]] = {{"tries", hostile_tries[k]}, {"answered", hostile_answered[k]}};
    for (const Sample& s : samples)
      j["samples"].push_back({{"t_s", s.t_s}, {"rss_kib", s.rss_kib}, {"heap_bytes", s.heap_bytes}, {"fds", s.fds}});
    j["fds_before"] = fds_before;
    j["fds_after"] = fds_after;
    std::ofstream(path) << j.dump(1) << "\n";
  }
}

// Issue 73's fault soak: the server's renderer buffer allocations fail at random
// (CATGS_FAIL_ALLOCATIONS, the CPU core's host slot), as on a GPU another process fills. Sessions
// come in at several viewports and resize every few frames, so their buffers grow mid-session.
// What must hold: no admitted session ends (a visitor the door refuses, ERROR_SERVER_FULL with a
// retry hint, tries again), every session keeps getting frames, the frames whose buffers could not
// grow are drawn anyway (Stats.memory_fallback_frames, catgs_render_memory_fallbacks_total), and
// the server's own counters agree. Length: CATGS_FAULT_SOAK_SECONDS (default 60), sessions:
// CATGS_FAULT_SOAK_SESSIONS (default 10), the share of allocations that fail:
// CATGS_FAULT_SOAK_P (default 0.25).
TEST(Soak, AllocationsFailingAtRandomEndNoSession) {
  const double seconds = env_number("CATGS_FAULT_SOAK_SECONDS", 60);
  const int sessions = static_cast<int>(env_number("CATGS_FAULT_SOAK_SESSIONS", 10));
  const double p = env_number("CATGS_FAULT_SOAK_P", 0.25);
  setenv("CATGS_FAIL_ALLOCATIONS", (std::to_string(p) + ",73").c_str(), 1);
  ServerProcess server(server_args(kBiker, {"--max-sessions", std::to_string(sessions + 4)}));
  unsetenv("CATGS_FAIL_ALLOCATIONS");
  ASSERT_NE(server.log().find("CATGS_FAIL_ALLOCATIONS"), std::string::npos) << server.log();
  const int port = server.port();
  const int sizes[][2] = {{64, 48}, {160, 96}, {96, 64}, {256, 144}, {128, 128}, {320, 180}};
  struct Result {
    int refusals = 0, frames = 0, resizes = 0, fallback_frames = 0;
    std::string error;
  };
  std::vector<Result> results(static_cast<std::size_t>(sessions));
  std::atomic<bool> stop{false};
  std::vector<std::thread> threads;
  for (int i = 0; i < sessions; ++i)
    threads.emplace_back([&, i] {
      Result& r = results[static_cast<std::size_t>(i)];
      try {
        std::unique_ptr<StreamClient> c;
        int size = i % 6;
        for (;;) {  // refused at the door: wait the hint, as a page does, and try again
          try {
            c = std::make_unique<StreamClient>();
            c->connect(port);
            c->hello(sizes[size][0], sizes[size][1]);
            break;
          } catch (const Refused& e) {
            if (e.error().code() != pb::ERROR_SERVER_FULL || ++r.refusals > 50) throw;
            std::this_thread::sleep_for(std::chrono::milliseconds(200));
          }
        }
        const Trace orbit = biker_orbit(64, 48, 24);
        std::uint32_t seq = 0;
        bool outstanding = false;
        while (!stop) {
          if (!outstanding) {
            const Camera& cam = orbit[seq % orbit.size()].camera;
            c->send_pose(pose_from_camera(cam, seq++, now_ms()));
            outstanding = true;
          }
          const auto m = c->recv(50);
          if (!m) continue;
          if (m->has_error()) throw std::runtime_error("session ended: " + m->error().reason());
          if (m->has_stats()) r.fallback_frames += static_cast<int>(m->stats().memory_fallback_frames());
          if (!m->has_frame()) continue;
          if (m->frame().pose_sequence() + 1 == seq) outstanding = false;
          if (++r.frames % 12 == 0) {  // a new viewport: its buffers grow, or not
            size = (size + 1 + i) % 6;
            pb::ClientMessage resize;
            resize.mutable_resize()->set_viewport_width(static_cast<std::uint32_t>(sizes[size][0]));
            resize.mutable_resize()->set_viewport_height(static_cast<std::uint32_t>(sizes[size][1]));
            c->send(resize);
            ++r.resizes;
          }
        }
      } catch (const std::exception& e) {
        r.error = e.what();
      }
    });
  const auto t0 = Clock::now();
  std::vector<int> frames_at_half(static_cast<std::size_t>(sessions), 0);
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds / 2));
  for (int i = 0; i < sessions; ++i)
    frames_at_half[static_cast<std::size_t>(i)] = results[static_cast<std::size_t>(i)].frames;
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds / 2));
  std::string metrics;
  ASSERT_EQ(http_get(port, "/metrics", metrics), 200);
  stop = true;
  for (auto& t : threads) t.join();
  const double ran = std::chrono::duration<double>(Clock::now() - t0).count();

  int refusals = 0, frames = 0, resizes = 0, fallback_frames = 0;
  for (int i = 0; i < sessions; ++i) {
    const Result& r = results[static_cast<std::size_t>(i)];
    EXPECT_EQ(r.error, "") << "session " << i;
    EXPECT_GT(r.frames, frames_at_half[static_cast<std::size_t>(i)]) << "session " << i << " stopped getting frames";
    refusals += r.refusals;
    frames += r.frames;
    resizes += r.resizes;
    fallback_frames += r.fallback_frames;
  }
  const double server_fallbacks = metric_value(metrics, "catgs_render_memory_fallbacks_total");
  const double dropped = metric_value(metrics, "catgs_render_out_of_memory_total");
  // Every Error the server sent was a refusal at the door.
  EXPECT_EQ(metric_value(metrics, "catgs_session_errors_total"), static_cast<double>(refusals)) << metrics;
  EXPECT_GT(server_fallbacks, 0.0) << "allocations failed mid-session and the frames were drawn anyway";
  EXPECT_GT(fallback_frames, 0) << "Stats.memory_fallback_frames told the sessions";
  EXPECT_LE(fallback_frames, server_fallbacks);
  EXPECT_EQ(metric_value(metrics, "catgs_memory_refusals_total"), static_cast<double>(refusals));
  EXPECT_LT(dropped, 0.05 * frames) << "frames lost after every fallback failed too";
  std::cout << "[ fault soak ] " << ran << " s, " << sessions << " sessions (CPU renderer), allocations failing with p "
            << p << ": " << frames << " frames, " << resizes << " resizes, " << server_fallbacks
            << " frames drawn after an allocation failed (" << fallback_frames << " in the sessions' Stats), "
            << dropped << " dropped after every fallback failed, " << refusals
            << " visitors refused at the door (retried), 0 "
            << "sessions ended\n";
}

}  // namespace
