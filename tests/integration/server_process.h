// Runs the real catgs-server binary as a child process for integration tests.
#pragma once

#include <sys/types.h>

#include <string>
#include <vector>

namespace catgs::itest {

class ServerProcess {
 public:
  // Which start-up line the constructor waits for.
  enum class Until {
    serving,  // "listening on http://127.0.0.1:PORT/": the scene is loaded, sessions are admitted
    probes,   // "probes on http://127.0.0.1:PORT/": HTTP answers, the scene may still be loading
  };
  // Starts CATGS_SERVER_BIN with `args` plus --port 0 (the kernel picks a free port) and waits
  // for the `until` line. stdout+stderr go to a temp log file.
  // Throws std::runtime_error when it exits or does not print the line within `timeout_ms`.
  explicit ServerProcess(const std::vector<std::string>& args, int timeout_ms = 20000, Until until = Until::serving);
  // SIGTERM, then SIGKILL after 5 s.
  ~ServerProcess();
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  int port() const { return port_; }
  // The server's process id (-1 once it has exited and been reaped).
  pid_t pid() const { return pid_; }
  // Sends SIGTERM and waits up to `timeout_ms`; returns the exit status (or -1 on timeout).
  int terminate(int timeout_ms = 10000);
  // Sends `sig` (no wait).
  void signal(int sig);
  // Waits up to `timeout_ms` for the process to exit; returns its exit code (128 + signal for a
  // signal death; also when it had already exited), or -1 on timeout.
  int wait_exit(int timeout_ms);
  bool running();
  // The server's output so far.
  std::string log() const;

 private:
  pid_t pid_ = -1;
  int exit_code_ = -1;  // once reaped
  int port_ = 0;
  std::string log_path_;
};

// Resident set size of process `pid` in KiB (VmRSS of /proc/PID/status); -1 when unreadable.
long rss_kib(pid_t pid);

// A TCP connection to 127.0.0.1:port: the socket, or -1 when it could not be made.
int connect_loopback(int port);

// GET http://127.0.0.1:port/path; returns the status code and fills `body` (-1: no answer).
// `extra_headers`: more request lines, each ending in "\r\n" (e.g. an Authorization header).
int http_get(int port, const std::string& path, std::string& body, int timeout_ms = 5000,
             const std::string& extra_headers = "");

}  // namespace catgs::itest
