// WebSocket + HTTP transport on libwebsockets 4.1.6, on its own service thread.
//
// lws is not thread-safe: only its service thread touches lws objects. Other threads call send()
// / close(), which queue under a mutex and wake the service thread with lws_cancel_service();
// the service thread then asks for writable callbacks (lws_cancel_service is the one lws call
// that is safe from another thread). Each connection has its own outgoing queue; large messages
// are written in fragments so one slow socket never blocks the loop. Handler callbacks run on the
// service thread and must return quickly (post work away).
//
// HTTP: "/" serves the web root (static files, extra MIME types for .mjs/.proto/.js/.json/.wasm),
// "/healthz" answers 200 "ok" whenever the process serves HTTP (liveness), "/readyz" answers
// Handler::readiness() (200, or 503 while the server cannot take a new session: routing),
// "/metrics" answers Handler::metrics_text() (Prometheus text). A static file asked for from a
// page of another origin carries Access-Control-Allow-Origin for it, so another site can import
// the viewer module (web_client/viewer/viewer.js) from this server; where that origin may not open
// a session (origin_policy.h), also `catgs-session-origin: refused`, so the viewer can say so.
// WebSocket: subprotocol "catgs.v1" (or none) on any path.
//
// Upgrades are checked before the handshake (issue 22): Sec-WebSocket-Version must be 13 (else
// 426 with the version we speak), the Origin must be allowed (origin_policy.h; else 403), and the
// caps on connections per client address (429) and on connections that have not said Hello yet
// (503) must have room. Each refusal is reported to TransportHandler::on_refused. An incoming
// message is cut off as soon as it is known to exceed max_message_bytes, by the length a frame
// declares before its payload is read: the connection stops reading and the handler is told
// (`oversize`) so the session can send its Error and close.
// lws 4.1.6 cannot refuse unmasked client frames (RFC 6455 5.1): its parser records the mask bit
// and carries on, and no public call exposes the bit (server/README.md "Limits").
//
// TLS (issue 22): with a certificate and key (tls_setup.h) the port speaks only TLS, HTTPS and
// WSS alike; a plain-HTTP request there fails the handshake and is closed unanswered. ALPN offers
// HTTP/1.1 alone: the upgrade checks above are made for HTTP/1.1 upgrades, and WebSockets over
// HTTP/2 (RFC 8441) would take another path through lws.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "transport/connection_link.h"
#include "transport/origin_policy.h"
#include "transport/tls_setup.h"
#include "transport/trusted_proxies.h"

struct lws;
struct lws_context;

namespace catgs::server {

// Why an upgrade was refused (TransportHandler::on_refused); also the /metrics label.
enum class Refusal { version, origin, per_ip, pre_hello };
inline constexpr int kRefusalKinds = 4;
const char* refusal_name(Refusal r);

class TransportHandler {
 public:
  virtual ~TransportHandler() = default;
  // A WebSocket connection opened.
  virtual void on_open(ConnId id) = 0;
  // One complete message. For `oversize` the bytes are empty (the message exceeded the limit and
  // was discarded).
  virtual void on_message(ConnId id, MessageKind kind, std::string bytes) = 0;
  // A message queued with send(..., counted = true) has been fully handed to the socket layer;
  // `socket` is its TCP_INFO right after (connection_link.h).
  virtual void on_sent(ConnId id, const SocketSample& socket) = 0;
  // The connection is gone (closed by either side or dropped). No callbacks follow for `id`.
  virtual void on_close(ConnId id) = 0;
  // Body of GET /metrics (Prometheus text format).
  virtual std::string metrics_text() = 0;
  // GET /readyz: the HTTP status (200 when a new session would be admitted, else 503) with a
  // one-line reason in `body`.
  virtual int readiness(std::string& body) = 0;
  // Body of GET /scenes (JSON: the scenes a Hello may name); "[]" until they are loaded.
  virtual std::string scenes_json() { return "[]\n"; }
  // GET /metrics with this Authorization header ("" when none): 200 to serve it, 401 (no or an
  // unknown token) or 403 (a token without the admin role) to refuse.
  virtual int metrics_access(const std::string& authorization) {
    (void)authorization;
    return 200;
  }
  // An upgrade was refused before the handshake: `peer` is the client address, `detail` says
  // what was wrong (e.g. the Origin).
  virtual void on_refused(Refusal why, const std::string& peer, const std::string& detail) {
    (void)why, (void)peer, (void)detail;
  }
};

struct TransportOptions {
  std::string bind = "0.0.0.0";
  int port = 8080;                            // 0: any free port (see Transport::port())
  std::string web_root;                       // static files at "/"
  std::size_t max_message_bytes = 64 * 1024;  // incoming messages above this are `oversize`
  int socket_send_buffer = 512 * 1024;        // SO_SNDBUF of WebSocket sockets; 0 = kernel's
  int notsent_lowat = 1024;                   // TCP_NOTSENT_LOWAT of WebSocket sockets; 0 = kernel's
  OriginPolicy origins = OriginPolicy();      // pages allowed to open a WebSocket
  int max_per_ip = 128;                       // WebSocket connections per client address; 0 = no cap
  int max_pre_hello = 256;                    // connections that have not said Hello; 0 = no cap
  TrustedProxies proxies;                     // whose X-Forwarded-For names the client (peer())
  std::string tls_cert, tls_key;              // PEM files; both set: TLS only (tls_setup.h)
};

class Transport final : public ConnectionLink {
 public:
  // The handler must outlive the transport.
  Transport(TransportOptions options, TransportHandler& handler);
  ~Transport();
  Transport(const Transport&) = delete;
  Transport& operator=(const Transport&) = delete;

  // Creates the lws context (binds the port) and starts the service thread. Throws
  // std::runtime_error when the port cannot be bound, or (before binding) when the TLS files do
  // not load (TlsCredentials::load's message names the file).
  void start();
  // Whether the port speaks TLS (options.tls_cert set).
  bool tls() const { return !options_.tls_cert.empty(); }
  // The credentials start() loaded (empty without TLS).
  const TlsCredentials& tls_credentials() const { return tls_credentials_; }
  // Thread-safe (SIGHUP). Reads options.tls_cert / tls_key again and waits until the service
  // thread has put them in place: handshakes from then on present the new certificate,
  // connections already open keep theirs. Returns the new credentials. Throws
  // std::runtime_error naming the file when they do not load (the old ones stay), or when TLS
  // is off or the transport is not running.
  TlsCredentials reload_tls();
  // Closes every connection, stops the service thread and destroys the context. Idempotent.
  void stop();
  // The port actually listened on (after start()).
  int port() const { return port_; }

  // Thread-safe. Queues one binary message. `counted` messages produce on_sent() once written.
  // Ignored when the connection is gone or closing.
  void send(ConnId id, std::string bytes, bool counted) override;
  // Thread-safe. Closes the connection after the queued messages are written (or after
  // `grace_ms` at most, for a peer that does not read). `drop_queued` discards messages not yet
  // started (used for too-slow clients, whose queue will never drain); `final_message`, when
  // non-empty, is queued last (an Error).
  void close(ConnId id, std::string final_message, bool drop_queued, int grace_ms = 2000) override;
  // Thread-safe. Messages queued for `id` and not yet fully written (0 for unknown ids).
  std::size_t queued(ConnId id) const override;
  // Thread-safe. The connection said a valid Hello: it no longer counts against max_pre_hello.
  void said_hello(ConnId id) override;
  // Thread-safe. The client's address ("" for unknown ids): the TCP peer, or behind a trusted
  // proxy the address its X-Forwarded-For names (trusted_proxies.h).
  std::string peer(ConnId id) const override;
  void set_send_buffer(ConnId id, int bytes) override;

 private:
  struct Outgoing {
    std::vector<unsigned char> buf;  // LWS_PRE bytes of headroom, then the payload
    std::size_t offset = 0;          // payload bytes written so far
    bool counted = false;
  };
  struct Conn {
    lws* wsi = nullptr;
    std::deque<Outgoing> queue;
    bool closing = false;      // no more sends accepted
    bool close_armed = false;  // the service thread has set the close timeout
    bool close_sent = false;   // the close frame is lws's now: it waits for the peer's answer
    int grace_ms = 2000;
    std::string rx;  // message being reassembled
    bool rx_oversize = false;
    bool rx_binary = true;  // opcode of the message's first fragment
    std::string peer;       // client address
    bool said_hello = false;
  };

  static int callback(lws* wsi, int reason, void* user, void* in, std::size_t len);
  int on_ws(lws* wsi, int reason, void* user, void* in, std::size_t len);
  int on_http(lws* wsi, int reason, void* user, void* in, std::size_t len);
  // LWS_CALLBACK_HTTP_CONFIRM_UPGRADE: 0 lets the upgrade go on, 1 when refused (answer written).
  int on_upgrade(lws* wsi, const char* upgrade);
  // Every HTTP request, its headers parsed, before lws routes it (files, probes, upgrades):
  // refuses ambiguous message framing with 400 (issue 22 finding 8: request smuggling through a
  // proxy that reads the length differently). Non-zero closes the connection.
  int on_http_filter(lws* wsi);
  // LWS_CALLBACK_ADD_HEADERS (a static file's answer): CORS for the origins that may open a
  // session, so a module script or fetch from such a page may read the file. Non-zero fails it.
  int on_add_headers(lws* wsi, void* in);
  // Appends one received fragment to its message; true when the message is complete (or known
  // to be oversize) and `kind` / `message` are set.
  bool take_fragment(lws* wsi, Conn& c, const void* in, std::size_t len, MessageKind& kind, std::string& message);
  int write_some(lws* wsi, ConnId id);
  // LWS_CALLBACK_OPENSSL_LOAD_EXTRA_SERVER_VERIFY_CERTS: lws made the vhost's SSL_CTX
  // (LWS_SERVER_OPTION_CREATE_VHOST_SSL_CTX, no certificate of its own); ours goes in.
  int on_ssl_context(ssl_ctx_st* ctx);
  // Service thread: installs credentials reload_tls() queued.
  void apply_pending_tls();
  void service_loop();
  void wake();

  TransportOptions options_;
  TransportHandler& handler_;
  lws_context* context_ = nullptr;
  std::thread thread_;
  std::atomic<bool> stopping_{false};
  int port_ = 0;

  mutable std::mutex mutex_;  // guards conns_ and dirty_
  std::unordered_map<ConnId, Conn> conns_;
  std::vector<ConnId> dirty_;                    // connections with new work for the service thread
  std::unordered_map<std::string, int> per_ip_;  // open WebSocket connections per address
  int pre_hello_ = 0;                            // open connections that have not said Hello
  // The client address on_upgrade worked out, for the ESTABLISHED callback that follows it on
  // this thread (the headers may be gone by then). Service thread only.
  lws* upgrading_wsi_ = nullptr;
  std::string upgrading_client_;
  ConnId next_id_ = 1;

  // TLS: what start() loaded (never changed after), the vhost's SSL_CTX (owned by lws; the
  // service thread's once started), and a reload waiting for that thread (guarded by mutex_).
  TlsCredentials tls_credentials_;
  ssl_ctx_st* ssl_ctx_ = nullptr;
  struct PendingTls {
    TlsCredentials credentials;
    std::promise<std::string> done;  // "" once installed, else why not
  };
  std::unique_ptr<PendingTls> pending_tls_;

  // Storage lws points into (must outlive the context).
  struct Static;
  std::unique_ptr<Static> static_;
};

}  // namespace catgs::server
