// Issue 22 (hardening), the pure pieces: token buckets and --rate-limits, the Origin policy, and
// access tokens (file format, roles, the constant-time compare).
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <fstream>

#include "session/access_tokens.h"
#include "session/rate_limit.h"
#include "transport/origin_policy.h"
#include "transport/trusted_proxies.h"

namespace {

using namespace catgs::server;
using Clock = std::chrono::steady_clock;

TEST(RateLimit, BucketAllowsTheBurstThenTheRate) {
  const auto t0 = Clock::now();
  TokenBucket b(RateSpec{2, 3}, t0);
  EXPECT_TRUE(b.take(t0));
  EXPECT_TRUE(b.take(t0));
  EXPECT_TRUE(b.take(t0));
  EXPECT_FALSE(b.take(t0)) << "past the burst";
  EXPECT_EQ(b.wait_ms(t0), 500u) << "one token at 2 a second";
  EXPECT_FALSE(b.take(t0 + std::chrono::milliseconds(400)));
  EXPECT_TRUE(b.take(t0 + std::chrono::milliseconds(600)));
  // Refill stops at the burst however long it was idle.
  const auto later = t0 + std::chrono::hours(1);
  EXPECT_TRUE(b.full(later));
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(b.take(later));
  EXPECT_FALSE(b.take(later));
}

TEST(RateLimit, OffMeansNoLimit) {
  const auto t0 = Clock::now();
  TokenBucket b(RateSpec{}, t0);
  for (int i = 0; i < 1000; ++i) ASSERT_TRUE(b.take(t0));
  EXPECT_EQ(b.wait_ms(t0), 0u);
}

TEST(RateLimit, ParsesTheFlag) {
  RateLimitSettings s;
  apply_rate_limits(s, "ping=2/4,hello=off,key_frame=0.5/1");
  EXPECT_EQ(s.ping.per_second, 2);
  EXPECT_EQ(s.ping.burst, 4);
  EXPECT_FALSE(s.hello.enabled());
  EXPECT_EQ(s.key_frame.per_second, 0.5);
  EXPECT_EQ(s.resize.per_second, RateLimitSettings{}.resize.per_second) << "untouched";
  for (const char* bad : {"ping=2", "ping=x/4", "ping=2/0.5", "nope=1/1", "ping", "ping=-1/3", "ping=1/3x"})
    EXPECT_THROW(apply_rate_limits(s, bad), std::invalid_argument) << bad;
}

TEST(RateLimit, PeerLimiterKeepsAddressesApart) {
  RateLimitSettings s;
  s.hello = {0.001, 2};
  s.auth = {0.001, 1};
  PeerLimiter p(s);
  std::uint32_t retry = 0;
  EXPECT_TRUE(p.take_hello("10.0.0.1", retry));
  EXPECT_TRUE(p.take_hello("10.0.0.1", retry));
  EXPECT_FALSE(p.take_hello("10.0.0.1", retry));
  EXPECT_GT(retry, 0u);
  EXPECT_TRUE(p.take_hello("10.0.0.2", retry)) << "another address has its own bucket";
  EXPECT_TRUE(p.may_try_token("10.0.0.1", retry));
  EXPECT_TRUE(p.may_try_token("10.0.0.1", retry)) << "asking takes nothing";
  p.token_failed("10.0.0.1");
  EXPECT_FALSE(p.may_try_token("10.0.0.1", retry));
  EXPECT_TRUE(p.may_try_token("10.0.0.2", retry));
}

TEST(OriginPolicy, OwnOriginLocalhostListedAndNoOrigin) {
  const OriginPolicy p(parse_origins("https://App.example/, http://b.example:8080"));
  struct Case {
    const char* origin;
    const char* host;
    bool allowed;
    const char* why;
  };
  const Case cases[] = {
      {"", "stream.example", true, "no Origin: not a browser"},
      {"https://stream.example", "stream.example", true, "own origin behind a TLS proxy"},
      {"http://stream.example:8080", "Stream.Example:8080", true, "own origin, any case"},
      {"http://stream.example:9090", "stream.example:8080", false, "another port"},
      {"http://localhost:5173", "stream.example", true, "localhost"},
      {"http://127.0.0.1", "stream.example", true, "127.0.0.1"},
      {"http://[::1]:3000", "stream.example", true, "[::1]"},
      {"https://app.example", "stream.example", true, "listed"},
      {"http://b.example:8080", "stream.example", true, "listed with its port"},
      {"http://b.example", "stream.example", false, "listed with a port"},
      {"https://evil.example", "stream.example", false, "another site"},
      {"https://localhost.evil.example", "stream.example", false, "localhost as a prefix"},
      {"null", "stream.example", false, "sandboxed frame"},
      {"file://", "stream.example", false, "file page"},
      {"https://user@stream.example", "stream.example", false, "credentials"},
  };
  for (const Case& c : cases) EXPECT_EQ(p.allows(c.origin, c.host), c.allowed) << c.origin << ": " << c.why;
  EXPECT_TRUE(OriginPolicy(parse_origins("*")).allows("https://evil.example", "stream.example"));
  EXPECT_THROW(parse_origins("app.example"), std::invalid_argument);
  EXPECT_THROW(parse_origins("ftp://app.example"), std::invalid_argument);
  EXPECT_THROW(parse_origins("https://app.example/path"), std::invalid_argument);
}

TEST(TrustedProxies, RangesAndTheForwardedClient) {
  const TrustedProxies p = TrustedProxies::parse("10.0.0.0/8, 192.168.1.7,fd00::/8");
  EXPECT_TRUE(p.contains("10.200.3.4"));
  EXPECT_FALSE(p.contains("11.0.0.1"));
  EXPECT_TRUE(p.contains("192.168.1.7"));
  EXPECT_FALSE(p.contains("192.168.1.8"));
  EXPECT_TRUE(p.contains("fd12::1"));
  EXPECT_FALSE(p.contains("fe80::1"));
  EXPECT_FALSE(p.contains("not-an-address"));
  EXPECT_TRUE(TrustedProxies::parse("172.16.0.0/12").contains("172.31.255.255"));
  EXPECT_FALSE(TrustedProxies::parse("172.16.0.0/12").contains("172.32.0.0"));
  // Only a trusted peer's header counts, and only its right-most entry that is not one of ours.
  EXPECT_EQ(client_address(p, "203.0.113.9", "198.51.100.1"), "203.0.113.9") << "an untrusted peer";
  EXPECT_EQ(client_address(p, "10.0.0.5", ""), "10.0.0.5") << "no header";
  EXPECT_EQ(client_address(p, "10.0.0.5", "198.51.100.1"), "198.51.100.1");
  EXPECT_EQ(client_address(p, "10.0.0.5", "1.2.3.4, 198.51.100.1, 10.0.0.9"), "198.51.100.1")
      << "the client wrote 1.2.3.4 itself";
  EXPECT_EQ(client_address(p, "10.0.0.5", "garbage"), "10.0.0.5");
  EXPECT_TRUE(TrustedProxies::parse("").empty());
  for (const char* bad : {"10.0.0.0/33", "host.example", "10.0.0.0/", "10.0.0.0/x", "::/129"})
    EXPECT_THROW(TrustedProxies::parse(bad), std::invalid_argument) << bad;
}

TEST(AccessTokens, ConstantTimeEqual) {
  EXPECT_TRUE(constant_time_equal("s3cret", "s3cret"));
  EXPECT_FALSE(constant_time_equal("s3cres", "s3cret"));
  EXPECT_FALSE(constant_time_equal("s3cret", "s3cret2"));
  EXPECT_FALSE(constant_time_equal("s3cret2", "s3cret"));
  EXPECT_FALSE(constant_time_equal("s3crets3cret", "s3cret")) << "a repeat of the secret";
  EXPECT_FALSE(constant_time_equal("", "s3cret"));
  EXPECT_TRUE(constant_time_equal("", ""));
}

TEST(AccessTokens, FileRolesAndRefusals) {
  char path[] = "/tmp/catgs-unit-tokens-XXXXXX";
  const int fd = mkstemp(path);
  ASSERT_GE(fd, 0);
  close(fd);
  auto write = [&](const char* text) { std::ofstream(path, std::ios::trunc) << text; };
  write("# comment\n\nviewer v1\nadmin a1\r\nbare\n");
  AccessTokens t;
  t.add_file(path);
  EXPECT_EQ(t.size(), 3u);
  EXPECT_EQ(t.role_of("v1"), Role::viewer);
  EXPECT_EQ(t.role_of("a1"), Role::admin);
  EXPECT_EQ(t.role_of("bare"), Role::admin) << "a bare token does everything, as --token did";
  EXPECT_EQ(t.role_of("v"), Role::none);
  EXPECT_EQ(t.role_of(""), Role::none);
  for (const char* bad : {"guest tok\n", "viewer a b\n", "# only a comment\n"}) {
    write(bad);
    AccessTokens u;
    EXPECT_THROW(u.add_file(path), std::invalid_argument) << bad;
  }
  std::remove(path);
  AccessTokens u;
  EXPECT_THROW(u.add_file(path), std::invalid_argument) << "missing file";
  EXPECT_THROW(u.add("", Role::viewer), std::invalid_argument);
}

}  // namespace
