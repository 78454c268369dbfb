// Runs the real catgs-server binary as a child process for integration tests.
#pragma once

#include <sys/types.h>

#include <string>
#include <vector>

namespace catgs::itest {

class ServerProcess {
 public:
  // Starts CATGS_SERVER_BIN with `args` plus --port 0 (the kernel picks a free port) and waits
  // for its "listening on http://127.0.0.1:PORT/" line. stdout+stderr go to a temp log file.
  // Throws std::runtime_error when it exits or does not listen within `timeout_ms`.
  explicit ServerProcess(const std::vector<std::string>& args, int timeout_ms = 20000);
  // SIGTERM, then SIGKILL after 5 s.
  ~ServerProcess();
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  int port() const { return port_; }
  // The server's process id (-1 once it has exited and been reaped).
  pid_t pid() const { return pid_; }
  // Sends SIGTERM and waits up to `timeout_ms`; returns the exit status (or -1 on timeout).
  int terminate(int timeout_ms = 10000);
  bool running();
  // The server's output so far.
  std::string log() const;

 private:
  pid_t pid_ = -1;
  int port_ = 0;
  std::string log_path_;
};

// Resident set size of process `pid` in KiB (VmRSS of /proc/PID/status); -1 when unreadable.
long rss_kib(pid_t pid);

// GET http://127.0.0.1:port/path; returns the status code and fills `body` (-1: no answer).
int http_get(int port, const std::string& path, std::string& body, int timeout_ms = 5000);

}  // namespace catgs::itest
