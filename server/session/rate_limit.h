// Rate limits on what a client may ask for (issue 22 finding 10): token buckets per session for
// Ping, KeyFrameRequest, Resize, Quality, DepthRequest, SaveAnnotations and ExportVideoRequest, and per client address for Hello and for failed
// token attempts (a Hello is the first message of a new connection, so its limit has to outlive
// one session). Beyond a limit the session ends with ERROR_RATE_LIMITED (session.cpp).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <string>
#include <unordered_map>

namespace catgs::server {

// A rate and a burst: `per_second` tokens are added each second up to `burst`; each request takes
// one. per_second <= 0 turns the limit off.
struct RateSpec {
  double per_second = 0;
  double burst = 0;
  bool enabled() const { return per_second > 0; }
};

// Every limit the server applies (--rate-limits name=RATE/BURST,...). The defaults are well
// above what the web client and catgs-loadgen send (server/README.md "Limits" says why each).
struct RateLimitSettings {
  RateSpec hello{20, 100};    // per address: Hellos (new sessions), e.g. a 64-session load test
  RateSpec auth{1, 10};       // per address: failed token attempts (was 4081 guesses a second)
  RateSpec ping{5, 20};       // per session: Ping (the page sends one every 2 s)
  RateSpec key_frame{5, 20};  // per session: KeyFrameRequest (each makes the next frame an IDR)
  RateSpec resize{4, 10};     // per session: Resize (each rebuilds the encoder: an IDR)
  RateSpec quality{4, 10};    // per session: Quality (each rebuilds the encoder: an IDR)
  // per session: DepthRequest (each visits every Gaussian on a worker; the page sends one per
  // click, walk mode about 10 a second while moving)
  RateSpec depth{20, 40};
  RateSpec save{1, 5};  // per session: SaveAnnotations (each rewrites a file beside the scene)
  // per session: ExportVideoRequest (the page sends one per click on "Export video"; a session
  // renders one export at a time and the server --export-max-concurrent, so this only bounds the
  // cost of checking requests: a person trying sizes against the caps stays well within it)
  RateSpec export_video{1, 10};
};

// Applies "name=RATE/BURST,..." (or name=off) to `settings`; names: hello, auth, ping,
// key_frame, resize, quality, depth, save, export. Throws std::invalid_argument naming the bad entry.
void apply_rate_limits(RateLimitSettings& settings, const std::string& list);
// "5 a second, burst 20": for Error reasons and logs.
std::string describe(const RateSpec& spec);
// The usage lines for --rate-limits.
std::string rate_limits_usage();

// One token bucket. Not thread-safe (a session's buckets live on its strand; PeerLimiter locks).
class TokenBucket {
 public:
  using Clock = std::chrono::steady_clock;
  TokenBucket() = default;
  TokenBucket(RateSpec spec, Clock::time_point now) : spec_(spec), tokens_(spec.burst), last_(now) {}
  // Takes one token; false when none is left (always true when the limit is off).
  bool take(Clock::time_point now);
  // True when a token is there, without taking it.
  bool has(Clock::time_point now);
  // Milliseconds until the next token (0 when one is there): Error.retry_after_ms.
  std::uint32_t wait_ms(Clock::time_point now);
  // Full again (an idle address whose entry can be forgotten).
  bool full(Clock::time_point now);

 private:
  void refill(Clock::time_point now);
  RateSpec spec_;
  double tokens_ = 0;
  Clock::time_point last_{};
};

// Per client address buckets for Hello and failed tokens. Thread-safe. Entries of addresses whose
// buckets are full again are dropped once there are many, so a scan of many addresses cannot
// grow it without bound.
class PeerLimiter {
 public:
  using Clock = TokenBucket::Clock;
  explicit PeerLimiter(const RateLimitSettings& settings) : settings_(settings) {}  // copied
  // A Hello from `address`: true when within the hello limit (takes a token).
  // `retry_ms` gets the wait when not.
  bool take_hello(const std::string& address, std::uint32_t& retry_ms);
  // Before a token is compared: true when `address` may still try one (takes nothing).
  bool may_try_token(const std::string& address, std::uint32_t& retry_ms);
  // A wrong token from `address`.
  void token_failed(const std::string& address);
  std::size_t addresses() const;

 private:
  struct Entry {
    TokenBucket hello, auth;
  };
  Entry& entry(const std::string& address, Clock::time_point now);  // mutex held
  // Takes (or only checks for) a token of `address`'s bucket `which`; retry_ms when there is none.
  bool ask(const std::string& address, TokenBucket Entry::*which, bool take, std::uint32_t& retry_ms);
  void prune(Clock::time_point now);  // mutex held

  const RateLimitSettings settings_;
  mutable std::mutex mutex_;
  std::unordered_map<std::string, Entry> entries_;
};

}  // namespace catgs::server
