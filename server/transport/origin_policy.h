// Which web pages may open a WebSocket to this server (issue 22 finding 10: cross-site WebSocket
// hijacking). Browsers send an Origin header with every WebSocket upgrade and scripts cannot
// forge it; without a check, any site a user visits could open a session with the user's
// network position (an intranet server, a token kept by the browser).
//
// Allowed by default: the page's own origin (Origin's host[:port] equals the Host header, the
// page served by this server, with http or https in front: a TLS proxy changes the scheme, not
// the host), and pages on localhost / 127.0.0.1 / [::1] at any port (a developer's page). Plus
// every origin listed with --allowed-origins ("*" allows all).
// An upgrade without Origin is allowed: only browsers send Origin, and browsers always send it
// with WebSocket upgrades, so its absence means a non-browser client (catgs-loadgen, a test, a
// native app), which could put any Origin it liked there anyway. The check protects users'
// browsers, not the server from arbitrary programs (the token and the limits do that).
#pragma once

#include <string>
#include <vector>

namespace catgs::server {

class OriginPolicy {
 public:
  // `extra`: normalised origins (parse_origins), or {"*"}.
  explicit OriginPolicy(std::vector<std::string> extra = {}) : extra_(std::move(extra)) {}
  // `origin`: the Origin header ("" when there is none); `host`: the Host header.
  bool allows(const std::string& origin, const std::string& host) const;

 private:
  std::vector<std::string> extra_;
};

// "https://a.example,http://b.example:8080" -> normalised origins (lower case, no trailing
// slash); "*" alone allows every origin. Throws std::invalid_argument for an entry that is not
// scheme://host[:port] with scheme http or https.
std::vector<std::string> parse_origins(const std::string& list);

}  // namespace catgs::server
