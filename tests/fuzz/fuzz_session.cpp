// Fuzz target: the session state machine (server/session/session.h) driven by a client's whole
// connection: any sequence of messages (binary, text, oversize), transport write
// acknowledgements and pauses, then the disconnect. The session runs as in the server (its
// strand, the render scheduler, the CPU renderer on a real scene chunk, x264 at the client's
// size) but on this thread alone: work runs when the input says so (a pause) and at the end, so a
// run is repeatable. Its connection is an in-memory ConnectionLink that checks what the session
// sends against the protocol (proto/catgs_stream.proto):
//   - the connection is closed at most once, with an Error as its last message, and nothing is
//     sent after it;
//   - Welcome comes at most once and before any Frame; Frames are the only counted messages;
//     their sequences rise by one from 0; the first Frame, and the first at a new size, is a key
//     frame (an IDR the client's decoder can start from); no Frame exceeds the largest viewport;
// and after the disconnect, once the queued work has run, that the session is destroyed and gave
// back its connection and session counts (a leak there would fill the server for good).
// Rejections (Error + close) are the expected answer to bad messages; a crash, a sanitizer report
// or a broken rule above (abort with the rule) is a finding.
//
// Input: records, each an op byte then its operands:
//   op % 8 == 0  binary message: u16 little-endian length, then that many bytes (fewer at the end)
//   op % 8 == 1  text message: the same layout (the session must refuse text)
//   op % 8 == 2  oversize message (the transport discarded one above 64 KiB)
//   op % 8 == 3  the transport wrote the oldest counted message not yet written (Frame)
//   op % 8 == 5  the renderer's next buffer allocation fails (issue 73, base/allocation_faults.h);
//                after one, a session that ends with "render/encode failed" is a finding (a
//                failed allocation must leave the renderer whole: the frame is drawn in passes or
//                coarser, or dropped, and the session goes on)
//   otherwise    a pause: the queued work (strand handlers, render and encode jobs) runs
// Seeds: corpus/session (make_session_seeds.py writes them from protobuf text).
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <iostream>
#include <memory>
#include <optional>
#include <string>

#include <boost/asio/executor_work_guard.hpp>

extern "C" {
#include <libavutil/log.h>
}

#include "base/allocation_faults.h"
#include "session/session.h"

namespace catgs::server {
namespace {

constexpr int kMaxSide = 64;  // --max-viewport for the fuzzed sessions: renders stay cheap

[[noreturn]] void broken(const std::string& rule) {
  std::fprintf(stderr, "fuzz_session: protocol rule broken: %s\n", rule.c_str());
  std::abort();
}

// The connection, in memory; checks the session's side of the protocol as messages go out.
class CheckingLink final : public ConnectionLink {
 public:
  void send(ConnId, std::string bytes, bool counted) override {
    if (closed_) broken("a message after the close");
    pb::ServerMessage m;
    if (!m.ParseFromString(bytes)) broken("a message that does not parse");
    if (counted != m.has_frame()) broken("counted messages must be exactly the Frames");
    if (m.has_error()) broken("an Error sent without closing");
    if (m.has_welcome()) {
      if (welcomed_) broken("a second Welcome");
      welcomed_ = true;
    }
    if (m.has_frame()) check_frame(m.frame());
    if (counted) unwritten_++;
  }
  void close(ConnId, std::string final_message, bool, int) override {
    if (closed_) broken("a second close");
    closed_ = true;
    pb::ServerMessage m;
    if (!m.ParseFromString(final_message) || !m.has_error() || m.error().code() == pb::ERROR_UNSPECIFIED)
      broken("a close without an Error as its last message");
    if (fault_injected && m.error().code() == pb::ERROR_INTERNAL &&
        m.error().reason().find("render/encode failed") != std::string::npos)
      broken("a render failed after an allocation failed: " + m.error().reason());
  }
  bool fault_injected = false;  // op 5 ran in this input
  std::size_t queued(ConnId) const override { return unwritten_; }
  void said_hello(ConnId) override {}
  void set_send_buffer(ConnId, int) override {}
  std::string peer(ConnId) const override { return "192.0.2.1"; }

  // Op 3: the oldest counted message was written; false when none is waiting.
  bool take_written() {
    if (unwritten_ == 0) return false;
    unwritten_--;
    return true;
  }

 private:
  void check_frame(const pb::Frame& f) {
    if (!welcomed_) broken("a Frame before Welcome");
    if (f.sequence() != next_sequence_) broken("Frame sequences must rise by one from 0");
    next_sequence_++;
    const bool new_size = !size_ || size_->first != f.width() || size_->second != f.height();
    if (new_size && !f.key_frame()) broken("the first Frame at a size must be a key frame");
    if (f.width() == 0 || f.height() == 0 || f.width() > kMaxSide || f.height() > kMaxSide)
      broken("a Frame outside the allowed viewport");
    size_ = std::make_pair(f.width(), f.height());
  }

  bool closed_ = false, welcomed_ = false;
  std::uint32_t next_sequence_ = 0;
  std::optional<std::pair<std::uint32_t, std::uint32_t>> size_;
  std::size_t unwritten_ = 0;
};

// Op 5's one-shot fault: armed, the next allocation the renderer asks the hook about fails.
std::atomic<bool> fault_armed{false};

// What outlives one input: the scene (loaded once), the strands' io_context and the render
// scheduler. Neither runs threads: settle() runs their work on this thread.
struct World {
  World() : work(io.get_executor()) {
    settings.max_viewport_width = kMaxSide;
    settings.max_viewport_height = kMaxSide;
    settings.frame.encoder = "x264";
    settings.frame.encoder_policy.threads = 1;
    SceneStore::Options o;  // no log: the chunk loads once, quietly
    scenes = std::make_unique<SceneStore>(
        std::vector<SceneStore::Source>{
            {std::string(CATGS_SOURCE_DIR) + "/tests/fuzz/corpus/scene/biker_chunk0.compressed.ply", ""}},
        std::move(o));
    scenes->load_now(0);
    render_options.pipeline = Pipeline::catgs;  // speculation and its caches: the most state
  }
  // Runs queued strand handlers, encode jobs and render jobs until none is left.
  void settle() {
    while (renders.poll() + io.poll() > 0) {}
  }

  boost::asio::io_context io;
  boost::asio::executor_work_guard<boost::asio::io_context::executor_type> work;
  RenderScheduler renders;  // never started: poll() runs its jobs here
  GpuAssignment gpus{{}};
  SessionSettings settings;
  RenderOptions render_options;
  std::unique_ptr<SceneStore> scenes;
};

World& world() {
  static World* w = [] {
    std::cerr.rdbuf(nullptr);        // the sessions' "[session ...]" log lines; sanitizers write to fd 2
    av_log_set_level(AV_LOG_QUIET);  // x264's per-encoder summaries
    set_allocation_fault([](std::uint64_t, const char*) { return fault_armed.exchange(false); });
    return new World();
  }();
  return *w;
}

std::uint16_t read_u16(const std::uint8_t*& p, const std::uint8_t* end) {
  std::uint16_t v = 0;
  for (int i = 0; i < 2 && p < end; ++i) v = static_cast<std::uint16_t>(v | (*p++ << (8 * i)));
  return v;
}

std::string read_bytes(const std::uint8_t*& p, const std::uint8_t* end) {
  const std::size_t n = std::min<std::size_t>(read_u16(p, end), static_cast<std::size_t>(end - p));
  std::string s(reinterpret_cast<const char*>(p), n);
  p += n;
  return s;
}

void run_connection(const std::uint8_t* data, std::size_t size) {
  World& w = world();
  CheckingLink link;
  ServerMetrics metrics;
  // Fresh per input: the per-address Hello and token limits start empty.
  SessionShared shared{w.io, w.renders, w.gpus, link, metrics, w.settings, *w.scenes, w.render_options, "cpu", "x264"};
  static ConnId next_id = 1;
  auto session = std::make_shared<Session>(next_id++, shared);
  session->start();
  const std::uint8_t* p = data;
  const std::uint8_t* end = data + size;
  while (p < end) {
    const std::uint8_t op = *p++ % 8;
    if (op == 0) {
      session->post_message(MessageKind::binary, read_bytes(p, end));
    } else if (op == 1) {
      session->post_message(MessageKind::text, read_bytes(p, end));
    } else if (op == 2) {
      session->post_message(MessageKind::oversize, {});
    } else if (op == 3) {
      if (link.take_written()) session->post_sent();
    } else if (op == 5) {
      fault_armed = true;
      link.fault_injected = true;
    } else {
      w.settle();
    }
  }
  session->post_closed();
  std::weak_ptr<Session> alive = session;
  session.reset();
  w.settle();
  fault_armed = false;
  if (!alive.expired()) broken("the session outlived its connection and its work");
  if (metrics.connections_open != 0) broken("the connection count was not given back");
  if (metrics.sessions_open != 0) broken("the session slot was not given back");
}

}  // namespace
}  // namespace catgs::server

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  catgs::server::run_connection(data, size);
  return 0;
}
