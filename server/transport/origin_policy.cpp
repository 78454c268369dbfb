#include "transport/origin_policy.h"

#include <algorithm>
#include <cctype>
#include <sstream>
#include <stdexcept>

namespace catgs::server {

namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

// "http://Host:1234/" -> "host:1234"; "" when it is not an http(s) origin.
std::string authority_of(const std::string& origin) {
  std::string o = lower(origin);
  while (!o.empty() && o.back() == '/') o.pop_back();
  for (const char* scheme : {"http://", "https://"}) {
    const std::string s = scheme;
    if (o.compare(0, s.size(), s) == 0) {
      std::string rest = o.substr(s.size());
      if (rest.empty() || rest.find_first_of("/?#@ ") != std::string::npos) return "";
      return rest;
    }
  }
  return "";
}

// "localhost:5173" -> "localhost"; "[::1]:80" -> "[::1]".
std::string hostname_of(const std::string& authority) {
  if (!authority.empty() && authority[0] == '[') {
    const auto end = authority.find(']');
    return end == std::string::npos ? authority : authority.substr(0, end + 1);
  }
  return authority.substr(0, authority.find(':'));
}

bool is_loopback_name(const std::string& host) { return host == "localhost" || host == "127.0.0.1" || host == "[::1]"; }

}  // namespace

bool OriginPolicy::allows(const std::string& origin, const std::string& host) const {
  if (origin.empty()) return true;  // not a browser (see the header)
  const std::string authority = authority_of(origin);
  if (authority.empty()) return false;  // "null" (sandboxed frames, file://) or not http(s)
  if (authority == lower(host)) return true;
  if (is_loopback_name(hostname_of(authority))) return true;
  std::string o = lower(origin);
  while (!o.empty() && o.back() == '/') o.pop_back();
  for (const std::string& e : extra_)
    if (e == "*" || e == o) return true;
  return false;
}

std::vector<std::string> parse_origins(const std::string& list) {
  std::vector<std::string> out;
  std::stringstream in(list);
  for (std::string entry; std::getline(in, entry, ',');) {
    entry.erase(0, entry.find_first_not_of(' '));
    entry.erase(entry.find_last_not_of(' ') + 1);
    if (entry.empty()) continue;
    if (entry == "*") {
      out.push_back("*");
      continue;
    }
    if (authority_of(entry).empty())
      throw std::invalid_argument("--allowed-origins: '" + entry +
                                  "' is not an origin (scheme://host[:port], scheme http or https)");
    std::string o = lower(entry);
    while (!o.empty() && o.back() == '/') o.pop_back();
    out.push_back(o);
  }
  return out;
}

}  // namespace catgs::server
