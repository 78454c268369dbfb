// Access tokens (issue 22 finding 10): where they come from, their roles, and how a candidate is
// compared with them.
//
// Sources, all merged: --token-file FILE (one token a line, "[viewer|author|admin] TOKEN"; a bare TOKEN
// and blank or # lines as below), the CATGS_TOKEN environment variable, and --token T (kept for
// compatibility, but anyone on the host can read a command line in /proc/PID/cmdline; the server
// warns). A token from CATGS_TOKEN, --token or a bare line is an admin token: one shared secret
// that does everything, as --token always did.
// Roles: viewer may open sessions (Hello.token); author may also save the scenes' annotations
// (hotspots, SaveAnnotations; issue 38); admin may do both and read /metrics (a bearer token).
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace catgs::server {

// Ordered: each role may do what the ones below it may.
enum class Role { none = 0, viewer = 1, author = 2, admin = 3 };

// True when a equals b. The time taken depends on a's length only (a is the candidate a client
// sent, b the secret): never on where the first difference is, nor on b's length, so timing
// tells a guesser nothing about the secret.
bool constant_time_equal(std::string_view a, std::string_view b);

class AccessTokens {
 public:
  // Adds one token with its role. Throws std::invalid_argument for an empty token.
  void add(std::string token, Role role);
  // Reads a token file (see above). Throws std::invalid_argument naming the file and line for
  // an unreadable file, an unknown role or a token with spaces, and when the file holds no token.
  void add_file(const std::string& path);
  bool empty() const { return tokens_.empty(); }
  std::size_t size() const { return tokens_.size(); }
  // The role of `candidate` (Role::none when it matches no token). Every token is compared in
  // constant time, and all of them are compared whatever matched.
  Role role_of(std::string_view candidate) const;

 private:
  struct Entry {
    std::string token;
    Role role;
  };
  std::vector<Entry> tokens_;
};

}  // namespace catgs::server
