#include "transport/trusted_proxies.h"

#include <arpa/inet.h>

#include <cstring>
#include <sstream>
#include <stdexcept>

namespace catgs::server {

namespace {

// A literal address into network-order bytes; family 0 when it is not one.
int to_bytes(const std::string& text, unsigned char (&out)[16]) {
  std::memset(out, 0, sizeof(out));
  if (inet_pton(AF_INET, text.c_str(), out) == 1) return AF_INET;
  if (inet_pton(AF_INET6, text.c_str(), out) == 1) return AF_INET6;
  return 0;
}

std::string trim(std::string s) {
  s.erase(0, s.find_first_not_of(" \t"));
  s.erase(s.find_last_not_of(" \t") + 1);
  return s;
}

}  // namespace

TrustedProxies TrustedProxies::parse(const std::string& list) {
  TrustedProxies t;
  std::stringstream in(list);
  for (std::string entry; std::getline(in, entry, ',');) {
    entry = trim(entry);
    if (entry.empty()) continue;
    const auto slash = entry.find('/');
    Net n;
    n.family = to_bytes(entry.substr(0, slash), n.bytes);
    const int bits = n.family == AF_INET ? 32 : 128;
    n.prefix = bits;
    if (n.family != 0 && slash != std::string::npos) {
      const std::string p = entry.substr(slash + 1);
      n.prefix =
          p.empty() || p.find_first_not_of("0123456789") != std::string::npos || p.size() > 3 ? -1 : std::stoi(p);
    }
    if (n.family == 0 || n.prefix < 0 || n.prefix > bits)
      throw std::invalid_argument("--trusted-proxies: '" + entry + "' is not an address or CIDR range");
    t.nets_.push_back(n);
  }
  return t;
}

bool TrustedProxies::contains(const std::string& address) const {
  unsigned char b[16];
  const int family = to_bytes(address, b);
  for (const Net& n : nets_) {
    if (n.family != family) continue;
    const int whole = n.prefix / 8, rest = n.prefix % 8;
    if (std::memcmp(b, n.bytes, static_cast<std::size_t>(whole)) != 0) continue;
    const unsigned char mask = static_cast<unsigned char>(0xff00 >> rest);
    if (rest == 0 || ((b[whole] ^ n.bytes[whole]) & mask) == 0) return true;
  }
  return false;
}

std::string client_address(const TrustedProxies& proxies, const std::string& peer, const std::string& forwarded_for) {
  if (forwarded_for.empty() || !proxies.contains(peer)) return peer;
  std::vector<std::string> hops;
  std::stringstream in(forwarded_for);
  for (std::string hop; std::getline(in, hop, ',');) hops.push_back(trim(hop));
  for (auto it = hops.rbegin(); it != hops.rend(); ++it) {
    unsigned char b[16];
    if (to_bytes(*it, b) == 0) return peer;
    if (!proxies.contains(*it)) return *it;
  }
  return hops.empty() ? peer : hops.front();  // every hop a proxy of ours: the first one
}

}  // namespace catgs::server
