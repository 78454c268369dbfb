// The client's address behind a reverse proxy (an Ingress, a load balancer). The per-address
// caps and rate limits (server/README.md "Limits") count the TCP peer; behind a proxy that is
// the proxy, shared by every user. --trusted-proxies names the proxies whose X-Forwarded-For
// header is believed; from anyone else the header is ignored, since any client can write one.
#pragma once

#include <string>
#include <vector>

namespace catgs::server {

class TrustedProxies {
 public:
  // "10.0.0.0/8,192.168.1.7,fd00::/8": addresses or CIDR ranges, IPv4 or IPv6. Throws
  // std::invalid_argument naming a bad entry.
  static TrustedProxies parse(const std::string& list);
  bool empty() const { return nets_.empty(); }
  // True when `address` (a literal, e.g. "10.1.2.3") is in one of the ranges.
  bool contains(const std::string& address) const;

 private:
  struct Net {
    int family = 0;
    unsigned char bytes[16] = {};
    int prefix = 0;  // leading bits that must match
  };
  std::vector<Net> nets_;
};

// The address limits should count for a connection from `peer` carrying `forwarded_for` (the
// X-Forwarded-For header, "" when absent): `peer` itself unless it is a trusted proxy; then the
// right-most X-Forwarded-For entry that is not a trusted proxy (entries to its left were written
// by the client and prove nothing). A malformed entry falls back to `peer`.
std::string client_address(const TrustedProxies& proxies, const std::string& peer, const std::string& forwarded_for);

}  // namespace catgs::server
