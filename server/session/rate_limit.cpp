#include "session/rate_limit.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

namespace catgs::server {

namespace {

double parse_number(const std::string& entry, const std::string& text) {
  std::size_t used = 0;
  double x = 0;
  try {
    x = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size() || !std::isfinite(x) || x <= 0 || x > 1e6)
    throw std::invalid_argument("--rate-limits: '" + entry + "' needs RATE/BURST, positive numbers (or off)");
  return x;
}

// "RATE/BURST" or "off".
RateSpec parse_spec(const std::string& entry, const std::string& value) {
  if (value == "off") return {};
  const auto slash = value.find('/');
  if (slash == std::string::npos)
    throw std::invalid_argument("--rate-limits: '" + entry + "' needs RATE/BURST (e.g. ping=5/20) or off");
  RateSpec s{parse_number(entry, value.substr(0, slash)), parse_number(entry, value.substr(slash + 1))};
  if (s.burst < 1) throw std::invalid_argument("--rate-limits: '" + entry + "': a burst below 1 admits nothing");
  return s;
}

// Beyond this many addresses, the idle ones (full buckets) are forgotten.
constexpr std::size_t kPruneAbove = 4096;

}  // namespace

void apply_rate_limits(RateLimitSettings& settings, const std::string& list) {
  std::stringstream in(list);
  for (std::string entry; std::getline(in, entry, ',');) {
    if (entry.empty()) continue;
    const auto eq = entry.find('=');
    if (eq == std::string::npos) throw std::invalid_argument("--rate-limits: '" + entry + "' needs name=RATE/BURST");
    const std::string name = entry.substr(0, eq);
    const RateSpec spec = parse_spec(entry, entry.substr(eq + 1));
    if (name == "hello")
      settings.hello = spec;
    else if (name == "auth")
      settings.auth = spec;
    else if (name == "ping")
      settings.ping = spec;
    else if (name == "key_frame")
      settings.key_frame = spec;
    else if (name == "resize")
      settings.resize = spec;
    else if (name == "quality")
      settings.quality = spec;
    else if (name == "depth")
      settings.depth = spec;
    else if (name == "save")
      settings.save = spec;
    else if (name == "export")
      settings.export_video = spec;
    else
      throw std::invalid_argument("--rate-limits: unknown limit '" + name +
                                  "' (hello, auth, ping, key_frame, resize, quality, depth, save, export)");
  }
}

std::string describe(const RateSpec& spec) {
  std::ostringstream o;
  o << spec.per_second << " a second, burst " << spec.burst;
  return o.str();
}

std::string rate_limits_usage() {
  // Written from the defaults themselves, so the help cannot drift from them.
  const RateLimitSettings d;
  struct Row {
    const char* name;
    const RateSpec& spec;
    const char* what;
  };
  const Row rows[] = {{"hello", d.hello, "Hellos per client address"},
                      {"auth", d.auth, "failed token attempts per client address"},
                      {"ping", d.ping, "Pings per session"},
                      {"key_frame", d.key_frame, "KeyFrameRequests per session"},
                      {"resize", d.resize, "Resizes per session"},
                      {"quality", d.quality, "Quality messages per session"},
                      {"depth", d.depth, "DepthRequests per session"},
                      {"save", d.save, "SaveAnnotations per session"},
                      {"export", d.export_video, "ExportVideoRequests per session"}};
  std::ostringstream o;
  for (const Row& r : rows) {
    std::ostringstream spec;
    spec << r.name << '=' << r.spec.per_second << '/' << r.spec.burst;
    o << "  " << std::left << std::setw(17) << spec.str() << r.what << '\n';
  }
  o << "  (RATE a second, BURST at once; name=off turns one off; beyond a limit: ERROR_RATE_LIMITED\n"
       "  and a close)\n";
  return o.str();
}

void TokenBucket::refill(Clock::time_point now) {
  if (now <= last_) return;
  const double seconds = std::chrono::duration<double>(now - last_).count();
  tokens_ = std::min(spec_.burst, tokens_ + seconds * spec_.per_second);
  last_ = now;
}

bool TokenBucket::take(Clock::time_point now) {
  if (!spec_.enabled()) return true;
  refill(now);
  if (tokens_ < 1) return false;
  tokens_ -= 1;
  return true;
}

bool TokenBucket::has(Clock::time_point now) {
  if (!spec_.enabled()) return true;
  refill(now);
  return tokens_ >= 1;
}

std::uint32_t TokenBucket::wait_ms(Clock::time_point now) {
  if (!spec_.enabled()) return 0;
  refill(now);
  if (tokens_ >= 1) return 0;
  return static_cast<std::uint32_t>(std::ceil((1 - tokens_) / spec_.per_second * 1000.0));
}

bool TokenBucket::full(Clock::time_point now) {
  if (!spec_.enabled()) return true;
  refill(now);
  return tokens_ >= spec_.burst;
}

PeerLimiter::Entry& PeerLimiter::entry(const std::string& address, Clock::time_point now) {
  auto it = entries_.find(address);
  if (it != entries_.end()) return it->second;
  if (entries_.size() >= kPruneAbove) prune(now);
  return entries_.emplace(address, Entry{TokenBucket(settings_.hello, now), TokenBucket(settings_.auth, now)})
      .first->second;
}

void PeerLimiter::prune(Clock::time_point now) {
  for (auto it = entries_.begin(); it != entries_.end();)
    it = it->second.hello.full(now) && it->second.auth.full(now) ? entries_.erase(it) : std::next(it);
}

bool PeerLimiter::ask(const std::string& address, TokenBucket Entry::*which, bool take, std::uint32_t& retry_ms) {
  const auto now = Clock::now();
  std::lock_guard<std::mutex> lock(mutex_);
  TokenBucket& bucket = entry(address, now).*which;
  if (take ? bucket.take(now) : bucket.has(now)) return true;
  retry_ms = bucket.wait_ms(now);
  return false;
}

bool PeerLimiter::take_hello(const std::string& address, std::uint32_t& retry_ms) {
  return ask(address, &Entry::hello, /*take=*/true, retry_ms);
}

bool PeerLimiter::may_try_token(const std::string& address, std::uint32_t& retry_ms) {
  return ask(address, &Entry::auth, /*take=*/false, retry_ms);
}

void PeerLimiter::token_failed(const std::string& address) {
  const auto now = Clock::now();
  std::lock_guard<std::mutex> lock(mutex_);
  entry(address, now).auth.take(now);
}

std::size_t PeerLimiter::addresses() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return entries_.size();
}

}  // namespace catgs::server
