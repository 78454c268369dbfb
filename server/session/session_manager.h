// Owns the sessions: maps transport connections to Session objects, enforces nothing itself
// (sessions do), serves /metrics and /readyz and drives the drain and the shutdown.
#pragma once

#include <utility>  // Boost 1.74 Asio under C++20 needs std::exchange declared first

#include <memory>
#include <mutex>
#include <unordered_map>

#include "session/session.h"
#include "transport/transport.h"

namespace catgs::server {

// Shared with the server's loading-phase handler (server.cpp), which answers before the manager
// exists: the /metrics verdict for an Authorization header, and the count and log line of an
// upgrade refusal.
int metrics_access_status(const AccessTokens& tokens, const std::string& authorization, ServerMetrics& metrics);
void count_refusal(ServerMetrics& metrics, Refusal why, const std::string& peer, const std::string& detail);

class SessionManager final : public TransportHandler {
 public:
  // `shared` must outlive the manager; its transport must be this manager's transport.
  explicit SessionManager(SessionShared& shared) : shared_(shared) {}

  // TransportHandler (service thread): forward to the session's strand.
  void on_open(ConnId id) override;
  void on_message(ConnId id, MessageKind kind, std::string bytes) override;
  void on_sent(ConnId id, const SocketSample& socket) override;
  void on_close(ConnId id) override;
  std::string metrics_text() override;
  std::string scenes_json() override;
  // 503 "draining" after start_draining(), 503 "full" while --max-sessions sessions are open,
  // else 200 "ready".
  int readiness(std::string& body) override;
  // /metrics: 200 without tokens, else only with an admin bearer token (401 / 403, counted).
  int metrics_access(const std::string& authorization) override;
  // Counts and logs an upgrade the transport refused.
  void on_refused(Refusal why, const std::string& peer, const std::string& detail) override;

  // The drain begins: /readyz turns 503 and every Hello from now on gets ERROR_SHUTTING_DOWN.
  // Live sessions go on. Thread-safe.
  // `deadline`: when the drain ends open sessions (Stats.drain_ms_left counts down to it).
  void start_draining(std::chrono::steady_clock::time_point deadline);
  // Sessions past Hello now (connections still awaiting Hello are not counted).
  std::int64_t open_sessions() const;

  // Sends ERROR_SHUTTING_DOWN to every connection and waits up to `wait_ms` for the connections to
  // close (the transport must still be running). Thread-safe.
  void shutdown(int wait_ms);
  // Connections currently known.
  std::size_t size() const;

 private:
  std::shared_ptr<Session> find(ConnId id) const;

  SessionShared& shared_;
  mutable std::mutex mutex_;
  std::unordered_map<ConnId, std::shared_ptr<Session>> sessions_;
};

}  // namespace catgs::server
