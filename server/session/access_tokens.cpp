#include "session/access_tokens.h"

#include <fstream>
#include <sstream>
#include <stdexcept>

namespace catgs::server {

bool constant_time_equal(std::string_view a, std::string_view b) {
  // Accumulate every difference (no early exit); the length difference is folded in too. b is
  // read cyclically so the loop length is a's alone.
  unsigned diff = a.size() == b.size() ? 0u : 1u;
  if (b.empty()) return a.empty();
  for (std::size_t i = 0; i < a.size(); ++i)
    diff |= static_cast<unsigned char>(a[i]) ^ static_cast<unsigned char>(b[i % b.size()]);
  return diff == 0;
}

void AccessTokens::add(std::string token, Role role) {
  if (token.empty()) throw std::invalid_argument("empty access token");
  tokens_.push_back({std::move(token), role});
}

void AccessTokens::add_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::invalid_argument("--token-file " + path + ": cannot read it");
  const std::size_t before = tokens_.size();
  int line_no = 0;
  for (std::string line; std::getline(in, line);) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();  // a file written on Windows
    std::istringstream words(line);
    std::string first, second, extra;
    words >> first >> second >> extra;
    if (first.empty() || first[0] == '#') continue;
    const std::string where = "--token-file " + path + " line " + std::to_string(line_no);
    if (!extra.empty()) throw std::invalid_argument(where + ": expected '[viewer|author|admin] TOKEN'");
    if (second.empty()) {
      add(first, Role::admin);
    } else if (first == "viewer") {
      add(second, Role::viewer);
    } else if (first == "author") {
      add(second, Role::author);
    } else if (first == "admin") {
      add(second, Role::admin);
    } else {
      throw std::invalid_argument(where + ": unknown role '" + first + "' (viewer, author or admin)");
    }
  }
  if (tokens_.size() == before) throw std::invalid_argument("--token-file " + path + ": no token in it");
}

Role AccessTokens::role_of(std::string_view candidate) const {
  Role best = Role::none;
  for (const Entry& e : tokens_) {
    // No short cut: which token matched (or that one did) must not show in the time taken.
    const bool match = constant_time_equal(candidate, e.token);
    if (match && static_cast<int>(e.role) > static_cast<int>(best)) best = e.role;
  }
  return best;
}

}  // namespace catgs::server
