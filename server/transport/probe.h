// `catgs-server --probe URL`: one HTTP GET for container health checks. Images have no curl, and
// /bin/sh (dash) cannot open TCP sockets, so the server binary probes itself (Dockerfile
// HEALTHCHECK, Kubernetes exec probes where httpGet cannot be used).
#pragma once

#include <string>

namespace catgs::server {

// The parts of an http:// or https:// URL the probe needs.
struct ProbeTarget {
  bool tls = false;          // https://
  std::string host;          // name or IPv4/IPv6 address (brackets removed)
  std::string port = "80";   // decimal (443 for https)
  std::string target = "/";  // path and query
};

// Parses "http[s]://HOST[:PORT][/PATH]". Throws std::invalid_argument naming the URL for anything
// else (another scheme, no host, a port that is not 1..65535).
ProbeTarget parse_probe_url(const std::string& url);

// GETs `url` with HTTP/1.1 (Boost.Beast), over TLS for https:// without checking the
// certificate (the probe asks a server whether it is alive, usually itself on 127.0.0.1 with a
// certificate made for its public name: who it is does not matter), giving up after `timeout_ms` for connect, write and
// read together. Returns the status code, or -1 when no answer came (refused, timed out, not
// HTTP); `error` then says why. Throws what parse_probe_url throws.
int probe_http(const std::string& url, int timeout_ms, std::string* error = nullptr);

}  // namespace catgs::server
