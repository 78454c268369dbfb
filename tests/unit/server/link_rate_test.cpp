// The link's rate controller (session/link_rate.h) against a simulated bottleneck: frames of the
// cap's size leave a server at 12 frames/s into a FIFO link of a given rate with a deep buffer
// (as tc's tbf with a large burst); a frame is written once the one before it has left (the
// server's TCP_NOTSENT_LOWAT), the round trip is the minimum plus the queue ahead, and the
// delivery rate is the link's while a queue stands (application-limited otherwise). With
// receipts, the client (its clock offset by an arbitrary amount) reports each frame's arrival
// (its last byte out of the link, plus half the minimum round trip) on its next pose, at 60 Hz,
// which reaches the server another half round trip later.
// The end-to-end numbers on a real shaped link are scripts/slow_link.sh's (RESULTS.md).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <chrono>
#include <vector>

#include <gtest/gtest.h>

#include "session/link_rate.h"

namespace catgs::server {
namespace {

using Clock = LinkRate::Clock;
using ms = std::chrono::duration<double, std::milli>;

struct Sim {
  LinkRate link;
  Clock::time_point t0 = Clock::now();
  double link_kbps = 1000;  // the bottleneck's rate now
  double busy_until = 0;    // ms: when the link has sent everything queued
  double ceiling = 400;     // the policy's rate, kbit/s on the wire
  double fps = 12;
  double min_rtt = 20;
  std::vector<double> delays;  // ms from a frame's hand-off to its last byte leaving the link
  std::vector<double> caps;
  bool receipts = false;
  double client_offset_ms = 987654.3;  // the client's clock minus the server's
  struct Receipt {
    double at_server, received_client, handed;
    std::uint32_t sequence;
    std::size_t bytes;
  };
  std::vector<Receipt> pending;  // sent by the client, not yet at the server
  std::uint32_t sequence = 0;

  // Receipts that reached the server by `t_ms`, in order.
  void deliver_receipts(double t_ms) {
    std::size_t k = 0;
    for (; k < pending.size() && pending[k].at_server <= t_ms; ++k) {
      const Receipt& r = pending[k];
      const double server_ms = std::chrono::duration<double, std::milli>(at(r.handed).time_since_epoch()).count();
      link.on_receipt({r.sequence, r.bytes, at(r.handed), at(r.handed), server_ms - r.handed + r.received_client},
                      at(r.at_server), static_cast<int>(ceiling));
    }
    pending.erase(pending.begin(), pending.begin() + static_cast<std::ptrdiff_t>(k));
  }

  Clock::time_point at(double t_ms) const { return t0 + std::chrono::duration_cast<Clock::duration>(ms(t_ms)); }
  // Runs `seconds` of frames from `from_ms`; returns the time after them.
  double run(double from_ms, double seconds) {
    const double step = 1000.0 / fps;
    double t = from_ms;
    for (; t < from_ms + seconds * 1000.0; t += step) {
      deliver_receipts(t);
      const double cap = link.cap_kbps(static_cast<int>(ceiling));
      caps.push_back(cap);
      const double bytes = cap * 1000.0 / 8.0 / fps;
      // Written when the frame before has left (a small unsent queue), then sent at the link's rate.
      const double written = std::max(t, busy_until - 1.0);
      const double start = std::max(written, busy_until);
      busy_until = start + bytes * 8.0 / link_kbps;  // kbit/s = bits per ms
      delays.push_back(busy_until - t);
      SocketSample s;
      s.valid = true;
      const double queue_ms = std::max(0.0, busy_until - written);
      s.rtt_ms = min_rtt + queue_ms;
      s.min_rtt_ms = min_rtt;
      s.app_limited = queue_ms < 1000.0 / fps;
      s.delivery_kbps = s.app_limited ? cap : link_kbps;
      link.on_written(static_cast<std::size_t>(bytes), at(t), at(written), s, static_cast<int>(ceiling));
      if (receipts) {
        const double arrived = busy_until + min_rtt / 2;
        const double pose = std::ceil(arrived / (1000.0 / 60)) * (1000.0 / 60);  // the client's next pose
        pending.push_back(
            {pose + min_rtt / 2, arrived + client_offset_ms, t, sequence, static_cast<std::size_t>(bytes)});
      }
      ++sequence;
    }
    return t;
  }
  double p95_delay(std::size_t from) const {
    std::vector<double> d(delays.begin() + static_cast<std::ptrdiff_t>(from), delays.end());
    std::sort(d.begin(), d.end());
    return d.empty() ? 0 : d[d.size() * 95 / 100];
  }
  double mean_cap(std::size_t from) const {
    double sum = 0;
    for (std::size_t k = from; k < caps.size(); ++k) sum += caps[k];
    return caps.size() > from ? sum / static_cast<double>(caps.size() - from) : 0;
  }
};

TEST(LinkRate, AFastLinkIsNeverLimited) {
  Sim sim;
  sim.link_kbps = 2000;  // five times the stream
  sim.run(0, 20);
  EXPECT_FALSE(sim.link.limited());
  EXPECT_EQ(sim.link.decreases(), 0);
  EXPECT_EQ(*std::min_element(sim.caps.begin(), sim.caps.end()), sim.ceiling);
}

// A link at 80%, 50% and 25% of the stream: after 3 s the frames' delay stays bounded and the
// link is used (the mean cap at least half the link's rate, never far above it).
TEST(LinkRate, ASlowLinkIsFollowedAndUsed) {
  for (double share : {0.8, 0.5, 0.25}) {
    Sim sim;  // no receipts: TCP_INFO alone
    sim.link_kbps = share * sim.ceiling;
    double t = sim.run(0, 3);
    const std::size_t settled = sim.delays.size();
    t = sim.run(t, 20);
    EXPECT_TRUE(sim.link.limited()) << share;
    EXPECT_LT(sim.p95_delay(settled), 500.0) << share;
    EXPECT_GT(sim.mean_cap(settled), 0.5 * sim.link_kbps) << share;
    EXPECT_LT(sim.mean_cap(settled), 1.1 * sim.link_kbps) << share;
    std::printf("link %.0f%%: p95 delay %.0f ms, mean cap %.0f of %.0f kbit/s, %d cuts\n", 100 * share,
                sim.p95_delay(settled), sim.mean_cap(settled), sim.link_kbps, sim.link.decreases());
  }
}

// The same with the client's receipts: the queue is read from them (whatever the clocks' offset),
// the delay stays lower still, and the link's rate is the one the receipts measure.
TEST(LinkRate, ReceiptsReadTheQueueAndTheLinksRate) {
  for (double share : {0.8, 0.5, 0.25}) {
    Sim sim;
    sim.receipts = true;
    sim.link_kbps = share * sim.ceiling;
    double t = sim.run(0, 3);
    const std::size_t settled = sim.delays.size();
    t = sim.run(t, 20);
    EXPECT_GT(sim.link.receipts(), 200) << share;
    EXPECT_TRUE(sim.link.limited()) << share;
    EXPECT_LT(sim.p95_delay(settled), 350.0) << share;
    EXPECT_GT(sim.mean_cap(settled), 0.6 * sim.link_kbps) << share;
    EXPECT_LT(sim.mean_cap(settled), 1.1 * sim.link_kbps) << share;
    EXPECT_NEAR(sim.link.link_kbps(), sim.link_kbps, 0.1 * sim.link_kbps) << share;
    std::printf("receipts, link %.0f%%: p95 delay %.0f ms, mean cap %.0f of %.0f kbit/s, %d cuts\n", 100 * share,
                sim.p95_delay(settled), sim.mean_cap(settled), sim.link_kbps, sim.link.decreases());
  }
}

// A receipt's queue is its one-way delay above the least one seen: 0 on an idle path whatever the
// clocks' offset, the wait of a frame that stood behind others.
TEST(LinkRate, ReceiptQueueIsTheDelayAboveItsBase) {
  LinkRate l;
  const auto t0 = Clock::now();
  const double offset = -5.0e6;  // the client's clock far behind the server's
  auto server_ms = [](Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(t.time_since_epoch()).count();
  };
  for (std::uint32_t k = 0; k < 5; ++k) {
    const auto handed = t0 + std::chrono::milliseconds(100 * k);
    l.on_receipt({k, 1000, handed, handed, server_ms(handed) + offset + 12.0}, handed + std::chrono::milliseconds(20),
                 400);
    EXPECT_NEAR(l.queue_ms(), 0.0, 1e-6) << k;
  }
  // A queue on the path delays every frame: two receipts in a row 200 ms above the base are
  // congestion; one alone may be a host that ran the client late.
  for (std::uint32_t k = 5; k < 7; ++k) {
    const auto handed = t0 + std::chrono::milliseconds(100 * k);
    l.on_receipt({k, 1000, handed, handed, server_ms(handed) + offset + 12.0 + 200.0},
                 handed + std::chrono::milliseconds(230), 400);
    EXPECT_NEAR(l.queue_ms(), 200.0, 1e-6);
    EXPECT_EQ(l.limited(), k == 6) << k << ": a 200 ms queue on two receipts in a row is congestion, on one not yet";
  }
}

// Frames every 100 ms; from the 6th on, the client's receipts run `late_ms` late and TCP's round
// trip sits `rtt_rise_ms` above its minimum. Returns the cuts the controller made.
int cuts_after_late_receipts(double rtt_rise_ms, double late_ms) {
  LinkRate l;
  const auto t0 = Clock::now();
  auto server_ms = [](Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(t.time_since_epoch()).count();
  };
  SocketSample s;
  s.valid = true;
  s.min_rtt_ms = 0.05;
  for (std::uint32_t k = 0; k < 40; ++k) {
    const auto handed = t0 + std::chrono::milliseconds(100 * k);
    s.rtt_ms = s.min_rtt_ms + (k < 5 ? 0.0 : rtt_rise_ms);
    l.on_written(3000, handed, handed + std::chrono::milliseconds(1), s, 4000);
    const double late = k < 5 ? 0.0 : late_ms;
    l.on_receipt({k, 3000, handed, handed, server_ms(handed) + 3.0 + late}, handed + std::chrono::milliseconds(20),
                 4000);
  }
  return l.decreases();
}

// A client busy between reads (a reference render, a slow decode) stamps its receipts late: a
// queue of 300 ms in them, while TCP's round trip stays at its minimum (its kernel acknowledged at
// once), is not the network's, and no cut follows; the same receipts with the round trip risen are.
TEST(LinkRate, LateReceiptsOverAnIdleNetworkAreNotCongestion) {
  EXPECT_EQ(cuts_after_late_receipts(0.25, 300.0), 0) << "late receipts over an idle network cut the rate";
  EXPECT_GT(cuts_after_late_receipts(40.0, 300.0), 0) << "receipts with the round trip risen are congestion";
}

// A host that runs the client or its browser late (issue 64: a page under CPU load) delays every
// receipt by 150 ms while TCP's round trip rises by 12 ms (the kernel acknowledged in time): not
// a queue on the network, no cut. The same receipts with the round trip risen by 150 ms: cut.
TEST(LinkRate, ReceiptsCountAsFarAsTheRoundTripRose) {
  EXPECT_EQ(cuts_after_late_receipts(12.0, 150.0), 0)
      << "receipts 150 ms late with the round trip up 12 ms cut the rate";
  EXPECT_GT(cuts_after_late_receipts(150.0, 150.0), 0) << "a queue that raised the round trip as much is congestion";
}

// A client that reads late closes its receive window: the socket holds unsent bytes and a frame
// waits 100-400 ms to be written, as on a slow link, but TCP_INFO says the receiver's window held
// it (tcpi_rwnd_limited). No cut, and the reading rate is not taken for the link's; the same
// delays with the window open (the network held it) are a slow link.
TEST(LinkRate, AFrameTheReceiversWindowHeldIsNotCongestion) {
  for (bool window_held : {true, false}) {
    LinkRate l;
    const auto t0 = Clock::now();
    SocketSample s;
    s.valid = true;
    s.min_rtt_ms = 0.05;
    s.rtt_ms = 0.1;
    double t_ms = 0;
    for (int k = 0; k < 60; ++k) {
      const double delay = 100.0 + 300.0 * ((k * 37) % 11) / 10.0;
      const auto handed = t0 + std::chrono::microseconds(static_cast<long>(t_ms * 1000));
      s.notsent_bytes = 20000;
      s.app_limited = false;
      s.delivery_kbps = 300;  // what the client read at
      s.busy_ms += delay;
      if (window_held) s.rwnd_limited_ms += 0.9 * delay;
      const auto written = handed + std::chrono::microseconds(static_cast<long>(delay * 1000));
      l.on_written(30000, handed, written, s, 4000);
      t_ms += delay + 16.0;
    }
    if (window_held) {
      EXPECT_EQ(l.decreases(), 0) << "a late reader's window cut the rate";
      EXPECT_FALSE(l.limited());
      EXPECT_EQ(l.link_kbps(), 0) << "the client's reading rate taken for the link's";
    } else {
      EXPECT_GT(l.decreases(), 0) << "the network held the frames: a slow link";
    }
  }
}

// A hostile client's receipts (any finite time the protocol lets through, sequences in any
// order) move only its own cap: it stays finite, within the floor and the ceiling, and so does the
// link's estimate.
TEST(LinkRate, HostileReceiptsKeepTheCapFinite) {
  LinkRate l;
  const auto t0 = Clock::now();
  const double times[] = {1e15, 5e-324, 0.0, 1e15, 1.0, 1e15 - 1, 2.0, 1e-300, 7e14, 3.0};
  for (int k = 0; k < 400; ++k) {
    const auto at = t0 + std::chrono::milliseconds(10 * k);
    const auto seq = static_cast<std::uint32_t>(k % 3 == 0 ? k : k + 1);
    l.on_receipt({seq, static_cast<std::size_t>(k % 7 == 0 ? 1u << 20 : 500), at, at, times[k % 10]}, at, 400);
    const int cap = l.cap_kbps(400);
    ASSERT_GE(cap, LinkRate::Params{}.floor_kbps) << k;
    ASSERT_LE(cap, 400) << k;
    ASSERT_TRUE(std::isfinite(l.link_kbps()) && l.link_kbps() <= 4 * 400) << k << ": " << l.link_kbps();
    ASSERT_TRUE(std::isfinite(l.queue_ms())) << k;
  }
}

// Unshaped -> 25% -> unshaped: the cap falls within a few seconds of the step down and is back
// at the policy's rate within 5 s of the step up (the link got faster: probing speeds up past the
// rate where it filled last time).
TEST(LinkRate, StepsDownAndBackUp) {
  for (bool receipts : {false, true}) {
    Sim sim;
    sim.receipts = receipts;
    sim.link_kbps = 4 * sim.ceiling;
    double t = sim.run(0, 5);
    EXPECT_FALSE(sim.link.limited()) << receipts;
    sim.link_kbps = 0.25 * sim.ceiling;
    const std::size_t down = sim.delays.size();
    t = sim.run(t, 10);
    EXPECT_TRUE(sim.link.limited()) << receipts;
    EXPECT_LT(sim.p95_delay(down + 36), 500.0) << receipts;  // from 3 s after the step
    sim.link_kbps = 4 * sim.ceiling;
    const std::size_t up = sim.caps.size();
    t = sim.run(t, 5);
    EXPECT_FALSE(sim.link.limited()) << receipts << ": still capped at " << sim.caps.back() << " 5 s after the step up";
    EXPECT_GT(sim.caps.size(), up);
  }
}

TEST(LinkRate, NeverBelowTheFloorAndTheGainFollowsTheEncoder) {
  LinkRate::Params p;
  p.floor_kbps = 80;
  Sim sim;
  sim.link = LinkRate(p);
  sim.link_kbps = 20;  // far below the floor
  sim.run(0, 10);
  EXPECT_GE(*std::min_element(sim.caps.begin(), sim.caps.end()), 80.0);
  // An encoder that overshoots the cap twice over: the gain asks it for less.
  LinkRate l(p);
  const auto t0 = Clock::now();
  SocketSample congested;
  congested.valid = true;
  congested.rtt_ms = 500;
  congested.min_rtt_ms = 10;
  congested.app_limited = false;
  congested.delivery_kbps = 200;
  l.on_written(3000, t0, t0 + std::chrono::milliseconds(300), congested, 400);
  ASSERT_TRUE(l.limited());
  const double cap = l.cap_kbps(400);
  SocketSample clear;
  clear.valid = true;
  clear.rtt_ms = 30;  // the queue has drained
  clear.min_rtt_ms = 10;
  for (int k = 1; k <= 10; ++k) {
    const auto at = t0 + std::chrono::milliseconds(300 + 100 * k);
    // Frames of twice the cap's share at 10 frames/s.
    l.on_written(static_cast<std::size_t>(2 * cap * 1000 / 8 / 10), at, at, clear, 400);
  }
  EXPECT_LT(l.encoder_gain(), 0.8);
}

TEST(LinkRate, FloorOfASize) {
  EXPECT_EQ(link_floor_kbps(640, 360), 138);
  EXPECT_EQ(link_floor_kbps(1280, 720), 552);
  EXPECT_EQ(link_floor_kbps(16, 16), 30);
}

}  // namespace
}  // namespace catgs::server
