#include "session/session_manager.h"

#include <chrono>
#include <iostream>
#include <thread>
#include <vector>

namespace catgs::server {

void SessionManager::on_open(ConnId id) {
  auto session = std::make_shared<Session>(id, shared_);
  session->start();
  std::lock_guard<std::mutex> lock(mutex_);
  sessions_[id] = std::move(session);
}

std::shared_ptr<Session> SessionManager::find(ConnId id) const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = sessions_.find(id);
  return it == sessions_.end() ? nullptr : it->second;
}

void SessionManager::on_message(ConnId id, MessageKind kind, std::string bytes) {
  if (auto s = find(id)) s->post_message(kind, std::move(bytes));
}

void SessionManager::on_sent(ConnId id, const SocketSample& socket) {
  if (auto s = find(id)) s->post_sent(socket);
}

void SessionManager::on_close(ConnId id) {
  std::shared_ptr<Session> s;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = sessions_.find(id);
    if (it == sessions_.end()) return;
    s = std::move(it->second);
    sessions_.erase(it);
  }
  s->post_closed();  // the session object lives until its last queued handler has run
}

std::string SessionManager::metrics_text() { return shared_.metrics.prometheus_text(); }

std::string SessionManager::scenes_json() { return shared_.scenes.json(); }

int SessionManager::metrics_access(const std::string& authorization) {
  return metrics_access_status(shared_.settings.tokens, authorization, shared_.metrics);
}

void SessionManager::on_refused(Refusal why, const std::string& peer, const std::string& detail) {
  count_refusal(shared_.metrics, why, peer, detail);
}

int metrics_access_status(const AccessTokens& tokens, const std::string& authorization, ServerMetrics& metrics) {
  if (tokens.empty()) return 200;
  static const std::string kBearer = "Bearer ";
  const bool bearer = authorization.compare(0, kBearer.size(), kBearer) == 0;
  const Role role = bearer ? tokens.role_of(std::string_view(authorization).substr(kBearer.size())) : Role::none;
  if (role == Role::admin) return 200;
  metrics.count(ServerMetrics::Unauthorized::metrics);
  return role == Role::none ? 401 : 403;
}

void count_refusal(ServerMetrics& metrics, Refusal why, const std::string& peer, const std::string& detail) {
  metrics.refused_upgrades_total[static_cast<int>(why)]++;
  std::cerr << "[transport " << peer << "] upgrade refused (" << refusal_name(why) << "): " << detail << "\n";
}

int SessionManager::readiness(std::string& body) {
  const std::int64_t open = open_sessions();
  const int limit = shared_.settings.max_sessions;
  if (shared_.draining) {
    body = "draining (" + std::to_string(open) + " sessions left)\n";
    return 503;
  }
  if (open >= limit) {
    body = "full (" + std::to_string(open) + "/" + std::to_string(limit) + " sessions)\n";
    return 503;
  }
  // Device memory (issue 61): no GPU has room for a session like the last visitor's, so a load
  // balancer sends the next one elsewhere.
  // The lesser of the accounting's room and the driver's (issue 73), read now; the body says which
  // binds.
  const std::uint64_t need = shared_.next_session_bytes;
  std::string binds;
  const std::uint64_t room = shared_.gpus.largest_room(&binds);
  if (need > 0 && room < need) {
    body = "full (no device memory for another session: " + memory_text(need) + " needed, " + memory_text(room) +
           " free by the " + (binds == "driver" ? "driver" : "server's accounting") + "; " + std::to_string(open) +
           " sessions)\n";
    return 503;
  }
  body = "ready (" + std::to_string(open) + "/" + std::to_string(limit) + " sessions)\n";
  return 200;
}

void SessionManager::start_draining(std::chrono::steady_clock::time_point deadline) {
  shared_.drain_deadline = deadline;
  shared_.draining = true;
}

std::int64_t SessionManager::open_sessions() const { return shared_.metrics.sessions_open.load(); }

std::size_t SessionManager::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return sessions_.size();
}

void SessionManager::shutdown(int wait_ms) {
  std::vector<std::shared_ptr<Session>> all;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto& [id, s] : sessions_) all.push_back(s);
  }
  for (auto& s : all) s->post_shutdown();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(wait_ms);
  while (size() > 0 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
}

}  // namespace catgs::server
