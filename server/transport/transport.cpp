#include "transport/transport.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <iostream>
#include <stdexcept>

#include <linux/tcp.h>  // struct tcp_info with the delivery rate (glibc's netinet/tcp.h lacks it)
#include <netinet/in.h>
#include <sys/socket.h>

#include <libwebsockets.h>

#include "process/thread_name.h"

namespace catgs::server {

namespace {

// Per-connection memory lws allocates (zeroed, no constructors run): the same layout for the
// WebSocket and HTTP protocols because lws may hand either kind of wsi to protocols[0].
struct Pss {
  ConnId id;  // WebSocket connections: our id (0 before ESTABLISHED)
};

// The transport whose lws_create_context() is running on this thread: lws hands over the vhost's
// SSL_CTX from inside it, with a vhost-setup wsi that may not lead back to the context's user pointer.
thread_local Transport* g_starting = nullptr;

// Outgoing WebSocket messages are written in fragments of this size: one lws_write per writable
// callback keeps the service loop responsive with many connections and big key frames.
constexpr std::size_t kFragmentBytes = 64 * 1024;

// TCP_INFO of a WebSocket's socket (connection_link.h SocketSample); valid false where it cannot
// be read (not TCP).
SocketSample socket_sample(lws* wsi) {
  SocketSample s;
  const int fd = static_cast<int>(lws_get_socket_fd(wsi));
  struct tcp_info info {};
  socklen_t len = sizeof info;
  if (fd < 0 || getsockopt(fd, IPPROTO_TCP, TCP_INFO, &info, &len) != 0) return s;
  // Older kernels fill less; the fields used here are from Linux 4.9-4.10 (delivery rate).
  if (len < offsetof(struct tcp_info, tcpi_delivery_rate) + sizeof info.tcpi_delivery_rate) return s;
  s.valid = true;
  s.rtt_ms = info.tcpi_rtt / 1000.0;
  s.min_rtt_ms = info.tcpi_min_rtt / 1000.0;
  s.delivery_kbps = static_cast<double>(info.tcpi_delivery_rate) * 8.0 / 1000.0;
  s.app_limited = info.tcpi_delivery_rate_app_limited != 0;
  s.notsent_bytes = info.tcpi_notsent_bytes;
  // Linux 4.10: the time the sender was busy and the part of it the receiver's window held it.
  if (len >= offsetof(struct tcp_info, tcpi_rwnd_limited) + sizeof info.tcpi_rwnd_limited) {
    s.busy_ms = static_cast<double>(info.tcpi_busy_time) / 1000.0;
    s.rwnd_limited_ms = static_cast<double>(info.tcpi_rwnd_limited) / 1000.0;
  }
  return s;
}

// A request header as a string ("" when absent).
std::string header(lws* wsi, lws_token_indexes token) {
  const int n = lws_hdr_total_length(wsi, token);
  if (n <= 0 || n > 4096) return "";
  std::string v(static_cast<std::size_t>(n) + 1, '\0');
  if (lws_hdr_copy(wsi, v.data(), n + 1, token) < 0) return "";
  v.resize(static_cast<std::size_t>(n));
  return v;
}

std::string peer_of(lws* wsi) {
  char buf[64] = {0};
  return lws_get_peer_simple(wsi, buf, sizeof(buf)) ? std::string(buf) : std::string();
}

// Writes a complete HTTP answer (status, an optional extra header, a body of `type`) in one
// write: on a connection that asked for an upgrade, and for our own paths (/healthz, /readyz,
// /scenes, /metrics), so that an answer never waits for a writable callback that a pipelined
// request's could overtake (issue 22, finding 8: two pipelined GET /healthz got two header blocks
// and no body). lws buffers what the socket does not take at once. False when it could not be
// written.
bool write_whole_response(lws* wsi, unsigned status, const std::string& body, lws_token_indexes extra = WSI_TOKEN_COUNT,
                          const std::string& extra_value = "", const char* type = "text/plain; charset=utf-8") {
  std::vector<unsigned char> buf(LWS_PRE + 1024 + body.size());
  unsigned char *start = buf.data() + LWS_PRE, *p = start, *end = buf.data() + buf.size() - body.size() - 1;
  if (lws_add_http_common_headers(wsi, status, type, body.size(), &p, end)) return false;
  if (extra != WSI_TOKEN_COUNT &&
      lws_add_http_header_by_token(wsi, extra, reinterpret_cast<const unsigned char*>(extra_value.data()),
                                   static_cast<int>(extra_value.size()), &p, end))
    return false;
  if (lws_finalize_http_header(wsi, &p, end)) return false;
  std::memcpy(p, body.data(), body.size());
  p += body.size();
  const int n = static_cast<int>(p - start);
  return lws_write(wsi, start, static_cast<std::size_t>(n), LWS_WRITE_HTTP) == n;
}

}  // namespace

const char* refusal_name(Refusal r) {
  switch (r) {
    case Refusal::version:
      return "version";
    case Refusal::origin:
      return "origin";
    case Refusal::per_ip:
      return "per_ip";
    case Refusal::pre_hello:
      return "pre_hello";
  }
  return "unknown";
}

// Everything lws keeps pointers to for the life of the context.
struct Transport::Static {
  lws_protocols protocols[3];
  lws_protocol_vhost_options mime[6];
  lws_http_mount mount_root, mount_healthz, mount_readyz, mount_metrics, mount_scenes;
  std::string web_root;
};

Transport::Transport(TransportOptions options, TransportHandler& handler)
    : options_(std::move(options)), handler_(handler), static_(std::make_unique<Static>()) {}

Transport::~Transport() { stop(); }

void Transport::start() {
  // Checked before anything binds: a bad file is named here (lws would only say "no context").
  if (tls()) tls_credentials_ = TlsCredentials::load(options_.tls_cert, options_.tls_key);
  Static& s = *static_;
  std::memset(s.protocols, 0, sizeof(s.protocols));
  // protocols[0] also receives WebSocket upgrades that name no subprotocol.
  s.protocols[0].name = "catgs.v1";
  s.protocols[0].callback = reinterpret_cast<lws_callback_function*>(&Transport::callback);
  s.protocols[0].per_session_data_size = sizeof(Pss);
  s.protocols[0].rx_buffer_size = 64 * 1024;
  s.protocols[0].tx_packet_size = kFragmentBytes + 1024;
  s.protocols[1].name = "http";
  s.protocols[1].callback = s.protocols[0].callback;
  s.protocols[1].per_session_data_size = sizeof(Pss);

  // MIME types lws does not know (it answers 415 for unknown extensions).
  const char* types[][2] = {{".mjs", "text/javascript"},   {".js", "text/javascript"},
                            {".proto", "text/plain"},      {".json", "application/json"},
                            {".wasm", "application/wasm"}, {".md", "text/markdown; charset=utf-8"}};
  constexpr int kTypes = static_cast<int>(sizeof(types) / sizeof(types[0]));
  for (int i = 0; i < kTypes; ++i) {
    std::memset(&s.mime[i], 0, sizeof(s.mime[i]));
    s.mime[i].next = i + 1 < kTypes ? &s.mime[i + 1] : nullptr;
    s.mime[i].name = types[i][0];
    s.mime[i].value = types[i][1];
  }

  s.web_root = options_.web_root;
  auto callback_mount = [](lws_http_mount& m, const char* path, const lws_http_mount* next) {
    std::memset(&m, 0, sizeof(m));
    m.mount_next = next;
    m.mountpoint = path;
    m.origin = "http";  // the protocol whose callback serves it
    m.origin_protocol = LWSMPRO_CALLBACK;
    m.mountpoint_len = static_cast<unsigned char>(std::strlen(path));
  };
  callback_mount(s.mount_scenes, "/scenes", nullptr);
  callback_mount(s.mount_metrics, "/metrics", &s.mount_scenes);
  callback_mount(s.mount_readyz, "/readyz", &s.mount_metrics);
  callback_mount(s.mount_healthz, "/healthz", &s.mount_readyz);
  std::memset(&s.mount_root, 0, sizeof(s.mount_root));
  s.mount_root.mount_next = &s.mount_healthz;
  s.mount_root.mountpoint = "/";
  s.mount_root.mountpoint_len = 1;
  s.mount_root.origin = s.web_root.c_str();
  s.mount_root.def = "index.html";
  s.mount_root.origin_protocol = LWSMPRO_FILE;
  s.mount_root.extra_mimetypes = &s.mime[0];
  // lws offers a file's answer to a protocol for extra headers (LWS_CALLBACK_ADD_HEADERS: CORS,
  // on_add_headers) only when the mount names one; a file that is missing still goes to on_http.
  s.mount_root.protocol = "http";

  lws_set_log_level(LLL_ERR, nullptr);
  lws_context_creation_info info;
  std::memset(&info, 0, sizeof(info));
  info.port = options_.port;
  info.iface = options_.bind.empty() ? nullptr : options_.bind.c_str();
  info.protocols = s.protocols;
  info.mounts = &s.mount_root;
  info.user = this;
  // Room for a request line and headers of up to 16 KiB (lws's default: 4 KiB), so that those
  // past our own limits (on_http_filter: 8 KiB) get 414 / 431 instead of a closed socket; past
  // 16 KiB lws still closes the connection without an answer.
  info.max_http_header_data = 16384;
  if (options_.bind.find(':') == std::string::npos) info.options |= LWS_SERVER_OPTION_DISABLE_IPV6;
  if (tls()) {
#if !defined(LWS_WITH_TLS)
    throw std::runtime_error("--tls-cert: this libwebsockets was built without TLS");
#endif
    // No file paths on purpose: lws makes an empty SSL_CTX for the vhost and hands it over
    // (on_ssl_context), where the checked credentials go now and a reload goes later.
    info.options |= LWS_SERVER_OPTION_DO_SSL_GLOBAL_INIT | LWS_SERVER_OPTION_CREATE_VHOST_SSL_CTX;
    info.alpn = "http/1.1";  // transport.h "TLS"
  }
  g_starting = this;
  context_ = lws_create_context(&info);
  g_starting = nullptr;
  if (context_ && tls() && !ssl_ctx_) {
    lws_context_destroy(context_);
    context_ = nullptr;
    throw std::runtime_error("--tls-cert: libwebsockets did not set up TLS");
  }
  if (!context_)
    throw std::runtime_error("cannot listen on " + options_.bind + ":" + std::to_string(options_.port) +
                             (tls() ? " with TLS" : "") + " (port in use or bad address?)");
  lws_vhost* vhost = lws_get_vhost_by_name(context_, "default");
  port_ = vhost ? lws_get_vhost_listen_port(vhost) : options_.port;
  stopping_ = false;
  thread_ = std::thread([this] {
    name_this_thread("catgs-lws");
    service_loop();
  });
}

void Transport::stop() {
  if (!thread_.joinable()) return;
  stopping_ = true;
  wake();
  thread_.join();
}

void Transport::service_loop() {
  while (!stopping_) {
    if (lws_service(context_, 0) < 0) break;
  }
  lws_context* ctx = nullptr;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ctx = context_;
    context_ = nullptr;  // wake() becomes a no-op from here on
  }
  // Closes every connection: CLOSED callbacks reach the handler from here.
  lws_context_destroy(ctx);
}

void Transport::wake() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (context_) lws_cancel_service(context_);
}

void Transport::send(ConnId id, std::string bytes, bool counted) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = conns_.find(id);
    if (it == conns_.end() || it->second.closing) return;
    Outgoing m;
    m.buf.resize(LWS_PRE + bytes.size());
    std::memcpy(m.buf.data() + LWS_PRE, bytes.data(), bytes.size());
    m.counted = counted;
    it->second.queue.push_back(std::move(m));
    dirty_.push_back(id);
    if (context_) lws_cancel_service(context_);
  }
}

void Transport::close(ConnId id, std::string final_message, bool drop_queued, int grace_ms) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = conns_.find(id);
  if (it == conns_.end() || it->second.closing) return;
  Conn& c = it->second;
  if (drop_queued) {
    // Keep a message already half written: the peer would see a broken frame otherwise.
    while (c.queue.size() > 1 || (c.queue.size() == 1 && c.queue.front().offset == 0)) c.queue.pop_back();
  }
  if (!final_message.empty()) {
    Outgoing m;
    m.buf.resize(LWS_PRE + final_message.size());
    std::memcpy(m.buf.data() + LWS_PRE, final_message.data(), final_message.size());
    c.queue.push_back(std::move(m));
  }
  c.closing = true;
  c.grace_ms = std::max(1, grace_ms);
  dirty_.push_back(id);
  if (context_) lws_cancel_service(context_);
}

std::size_t Transport::queued(ConnId id) const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = conns_.find(id);
  return it == conns_.end() ? 0 : it->second.queue.size();
}

void Transport::said_hello(ConnId id) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = conns_.find(id);
  if (it == conns_.end() || it->second.said_hello) return;
  it->second.said_hello = true;
  pre_hello_--;
}

void Transport::set_send_buffer(ConnId id, int bytes) {
  std::lock_guard<std::mutex> lock(mutex_);  // the entry, and so its socket, lives while held
  auto it = conns_.find(id);
  if (it == conns_.end() || !it->second.wsi) return;
  const int fd = static_cast<int>(lws_get_socket_fd(it->second.wsi));
  if (fd >= 0) setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &bytes, sizeof(bytes));
}

std::string Transport::peer(ConnId id) const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = conns_.find(id);
  return it == conns_.end() ? std::string() : it->second.peer;
}

// Runs before the handshake, with the request's headers at hand: a refusal here is an ordinary
// HTTP answer the client can read, and no WebSocket (or session) is ever created for it.
int Transport::on_upgrade(lws* wsi, const char* upgrade) {
  if (!upgrade || std::strcmp(upgrade, "websocket") != 0) return 0;
  const std::string peer = client_address(options_.proxies, peer_of(wsi), header(wsi, WSI_TOKEN_X_FORWARDED_FOR));
  upgrading_wsi_ = wsi;
  upgrading_client_ = peer;
  auto refuse = [&](Refusal why, unsigned status, const std::string& detail, lws_token_indexes extra = WSI_TOKEN_COUNT,
                    const std::string& extra_value = "") {
    handler_.on_refused(why, peer, detail);
    return write_whole_response(wsi, status, detail + "\n", extra, extra_value) ? 1 : -1;
  };
  // RFC 6455 4.2.2: a server that does not speak the client's version answers 426 with the
  // versions it does (lws 4.1.6 would carry on as if it were 13).
  const std::string version = header(wsi, WSI_TOKEN_VERSION);
  if (version != "13")
    return refuse(Refusal::version, 426, "unsupported Sec-WebSocket-Version '" + version + "' (13 only)",
                  WSI_TOKEN_VERSION, "13");
  const std::string origin = header(wsi, WSI_TOKEN_ORIGIN);
  if (!options_.origins.allows(origin, header(wsi, WSI_TOKEN_HOST)))
    return refuse(Refusal::origin, HTTP_STATUS_FORBIDDEN,
                  "origin '" + origin + "' may not open a session here (--allowed-origins)");
  int from_peer = 0, pre_hello = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = per_ip_.find(peer);
    from_peer = it == per_ip_.end() ? 0 : it->second;
    pre_hello = pre_hello_;
  }
  if (options_.max_per_ip > 0 && from_peer >= options_.max_per_ip)
    return refuse(Refusal::per_ip, 429,
                  "too many connections from " + peer + " (" + std::to_string(options_.max_per_ip) +
                      ", --max-connections-per-ip)",
                  WSI_TOKEN_HTTP_RETRY_AFTER, "5");
  if (options_.max_pre_hello > 0 && pre_hello >= options_.max_pre_hello)
    return refuse(
        Refusal::pre_hello, HTTP_STATUS_SERVICE_UNAVAILABLE,
        "too many connections waiting for Hello (" + std::to_string(options_.max_pre_hello) + ", --max-pre-hello)",
        WSI_TOKEN_HTTP_RETRY_AFTER, "2");
  return 0;
}

int Transport::on_ssl_context(ssl_ctx_st* ctx) {
  try {
    tls_credentials_.install(ctx);
  } catch (const std::exception& e) {
    std::cerr << "catgs-server: --tls-cert " << options_.tls_cert << ": " << e.what() << std::endl;
    return 1;  // lws fails the context
  }
  ssl_ctx_ = ctx;
  return 0;
}

TlsCredentials Transport::reload_tls() {
  if (!tls()) throw std::runtime_error("TLS is off (no --tls-cert)");
  TlsCredentials fresh = TlsCredentials::load(options_.tls_cert, options_.tls_key);
  auto pending = std::make_unique<PendingTls>();
  pending->credentials = fresh;
  std::future<std::string> done = pending->done.get_future();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!context_) throw std::runtime_error("the transport is not running");
    pending_tls_ = std::move(pending);
    lws_cancel_service(context_);
  }
  // The SSL_CTX is the service thread's: it makes new connections from it.
  if (done.wait_for(std::chrono::seconds(5)) != std::future_status::ready)
    throw std::runtime_error("the service thread did not take the new certificate within 5 s");
  const std::string error = done.get();
  if (!error.empty()) throw std::runtime_error(error);
  return fresh;
}

void Transport::apply_pending_tls() {
  std::unique_ptr<PendingTls> pending;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending.swap(pending_tls_);
  }
  if (!pending) return;
  try {
    pending->credentials.install(ssl_ctx_);
    pending->done.set_value("");
  } catch (const std::exception& e) {
    pending->done.set_value(e.what());
  }
}

int Transport::callback(lws* wsi, int reason, void* user, void* in, std::size_t len) {
  if (reason == LWS_CALLBACK_OPENSSL_LOAD_EXTRA_SERVER_VERIFY_CERTS)
    return g_starting ? g_starting->on_ssl_context(static_cast<ssl_ctx_st*>(user)) : 1;
  auto* self = static_cast<Transport*>(lws_context_user(lws_get_context(wsi)));
  switch (reason) {
    case LWS_CALLBACK_HTTP_CONFIRM_UPGRADE:
      return self->on_upgrade(wsi, static_cast<const char*>(in));
    case LWS_CALLBACK_FILTER_HTTP_CONNECTION:
      return self->on_http_filter(wsi);
    case LWS_CALLBACK_ADD_HEADERS:
      return self->on_add_headers(wsi, in);
    case LWS_CALLBACK_HTTP:
    case LWS_CALLBACK_HTTP_WRITEABLE:
    case LWS_CALLBACK_CLOSED_HTTP:
    case LWS_CALLBACK_HTTP_DROP_PROTOCOL:
      return self->on_http(wsi, reason, user, in, len);
    case LWS_CALLBACK_ESTABLISHED:
    case LWS_CALLBACK_RECEIVE:
    case LWS_CALLBACK_SERVER_WRITEABLE:
    case LWS_CALLBACK_CLOSED:
    case LWS_CALLBACK_EVENT_WAIT_CANCELLED:
      return self->on_ws(wsi, reason, user, in, len);
    default:
      // Static file serving and the HTTP plumbing live in lws's default handler.
      return lws_callback_http_dummy(wsi, static_cast<lws_callback_reasons>(reason), user, in, len);
  }
}

int Transport::on_http_filter(lws* wsi) {
  // Over-long request lines and headers (issue 22 finding 8: they got a closed socket). lws keeps
  // the headers it knows by token; their total stands for the header block.
  constexpr int kMaxUri = 8192, kMaxHeaders = 8192;
  if (lws_hdr_total_length(wsi, WSI_TOKEN_GET_URI) > kMaxUri) {
    std::cerr << "http: 414 for " << peer_of(wsi) << ": request target over " << kMaxUri << " bytes\n";
    lws_return_http_status(wsi, HTTP_STATUS_REQ_URI_TOO_LONG, "request target over 8192 bytes");
    return 1;
  }
  int header_bytes = 0;
  for (int t = 0; t < static_cast<int>(WSI_TOKEN_COUNT); ++t)
    if (t != WSI_TOKEN_GET_URI)
      header_bytes += std::max(0, lws_hdr_total_length(wsi, static_cast<lws_token_indexes>(t)));
  if (header_bytes > kMaxHeaders) {
    std::cerr << "http: 431 for " << peer_of(wsi) << ": headers over " << kMaxHeaders << " bytes\n";
    lws_return_http_status(wsi, 431, "headers over 8192 bytes");
    return 1;
  }
  // RFC 9112 6.3: a message with both Transfer-Encoding and Content-Length, or with Content-Length
  // given twice, has no single length; a server must not guess (a proxy in front may have guessed
  // otherwise, and the rest of the bytes would be read as another request). lws 4.1.6 serves such
  // requests: refuse them here, for every path (page files included), and close.
  const bool chunked = lws_hdr_total_length(wsi, WSI_TOKEN_HTTP_TRANSFER_ENCODING) > 0;
  const bool length = lws_hdr_total_length(wsi, WSI_TOKEN_HTTP_CONTENT_LENGTH) > 0;
  const bool twice = lws_hdr_fragment_length(wsi, WSI_TOKEN_HTTP_CONTENT_LENGTH, 1) > 0;
  // A GET with a body (Content-Length above 0, or chunked): lws 4.1.6 answers the GET and leaves
  // the body in the stream, where it was read as the next request (issue 22, finding 8). Nothing
  // we serve takes a body: refuse, and close, before the body's bytes are read.
  // header() gives "" for a value it will not copy (over 4 KiB): that counts as a body too.
  const std::string declared = length ? header(wsi, WSI_TOKEN_HTTP_CONTENT_LENGTH) : "0";
  const bool body = chunked || declared.empty() || declared.find_first_not_of("0 \t") != std::string::npos;
  if (!(chunked && length) && !twice && lws_hdr_total_length(wsi, WSI_TOKEN_GET_URI) > 0 && body) {
    std::cerr << "http: 400 for " << peer_of(wsi) << ": a GET with a body\n";
    lws_return_http_status(wsi, HTTP_STATUS_BAD_REQUEST, "a GET request carries no body");
    return 1;
  }
  if (!(chunked && length) && !twice) return 0;
  std::cerr << "http: 400 for " << peer_of(wsi) << ": "
            << (twice ? "Content-Length given twice" : "both Transfer-Encoding and Content-Length") << "\n";
  lws_return_http_status(wsi, HTTP_STATUS_BAD_REQUEST,
                         twice ? "Content-Length given twice" : "both Transfer-Encoding and Content-Length");
  return 1;
}

// A page on another site embeds the viewer with <script type="module"
// src="https://this/viewer/viewer.js">: module scripts (and the fetch of the schema beside them)
// are CORS requests, which the browser lets the page read only with Access-Control-Allow-Origin.
// The files are public, so every origin may read them: a site that may not open a session still
// gets the viewer, which then says why in its own box instead of staying an empty 0x0 element.
// Such a site's answers carry `catgs-session-origin: refused` (exposed to the page), read by the
// viewer's schema fetch (web_client/viewer/protocol.js). The answer varies with Origin, so caches
// keep one per origin.
int Transport::on_add_headers(lws* wsi, void* in) {
  // lws asks here for the WebSocket handshake's 101 too: that answer needs no CORS.
  if (lws_hdr_total_length(wsi, WSI_TOKEN_UPGRADE) > 0) return 0;
  const std::string origin = header(wsi, WSI_TOKEN_ORIGIN);
  if (origin.empty()) return 0;
  auto* args = static_cast<lws_process_html_args*>(in);
  auto* p = reinterpret_cast<unsigned char*>(args->p);
  unsigned char* end = p + args->max_len;
  auto add = [&](const char* name, const std::string& value) {
    return lws_add_http_header_by_name(wsi, reinterpret_cast<const unsigned char*>(name),
                                       reinterpret_cast<const unsigned char*>(value.data()),
                                       static_cast<int>(value.size()), &p, end) == 0;
  };
  if (!add("access-control-allow-origin:", origin) || !add("vary:", "Origin")) return 1;
  if (!options_.origins.allows(origin, header(wsi, WSI_TOKEN_HOST)) &&
      (!add("catgs-session-origin:", "refused") || !add("access-control-expose-headers:", "catgs-session-origin"))) {
    return 1;
  }
  args->max_len -= static_cast<int>(p - reinterpret_cast<unsigned char*>(args->p));
  args->p = reinterpret_cast<char*>(p);
  return 0;
}

int Transport::on_http(lws* wsi, int reason, void* user, void* in, std::size_t len) {
  switch (reason) {
    case LWS_CALLBACK_HTTP: {
      char uri[256] = {0};
      if (lws_hdr_copy(wsi, uri, sizeof(uri), WSI_TOKEN_GET_URI) < 0) uri[0] = 0;
      std::string path = uri;
      std::string body, type = "text/plain; charset=utf-8";
      unsigned status = HTTP_STATUS_OK;
      // Exact paths: lws hands this callback every URI its mounts' prefixes match (/healthzXYZ,
      // /metrics/foo), and those are not ours to answer (issue 22, finding 8).
      if (path == "/healthz") {
        body = "ok\n";
      } else if (path == "/readyz") {
        status = static_cast<unsigned>(handler_.readiness(body));
      } else if (path == "/scenes") {
        body = handler_.scenes_json();
        type = "application/json";
      } else if (path == "/metrics") {
        // Behind the admin token when the server has tokens; /healthz and /readyz stay open
        // for probes, which carry no credentials.
        status = static_cast<unsigned>(handler_.metrics_access(header(wsi, WSI_TOKEN_HTTP_AUTHORIZATION)));
        if (status == HTTP_STATUS_OK) {
          body = handler_.metrics_text();
          type = "text/plain; version=0.0.4; charset=utf-8";
        } else {
          body = status == HTTP_STATUS_UNAUTHORIZED ? "a token is required: Authorization: Bearer TOKEN\n"
                                                    : "this token may not read /metrics (admin only)\n";
        }
      } else {
        if (lws_return_http_status(wsi, HTTP_STATUS_NOT_FOUND, nullptr)) return -1;
        return lws_http_transaction_completed(wsi) ? -1 : 0;
      }
      const bool bearer = status == HTTP_STATUS_UNAUTHORIZED;
      if (!write_whole_response(wsi, status, body, bearer ? WSI_TOKEN_HTTP_WWW_AUTHENTICATE : WSI_TOKEN_COUNT,
                                bearer ? "Bearer realm=\"catgs\"" : "", type.c_str()))
        return -1;
      return lws_http_transaction_completed(wsi) ? -1 : 0;
    }
    default:  // writable, closed: our answers are written whole above
      break;
  }
  return lws_callback_http_dummy(wsi, static_cast<lws_callback_reasons>(reason), user, in, len);
}

// Longer than the rest on purpose: libwebsockets drives a connection through one callback with a
// reason code, and this switch is that state machine in one place (one short case per reason).
int Transport::on_ws(lws* wsi, int reason, void* user, void* in, std::size_t len) {
  auto* pss = static_cast<Pss*>(user);
  switch (reason) {
    case LWS_CALLBACK_ESTABLISHED: {
      ConnId id;
      const std::string peer = upgrading_wsi_ == wsi ? upgrading_client_ : peer_of(wsi);
      upgrading_wsi_ = nullptr;
      {
        // Counted here, checked in on_upgrade: the handshake between the two runs in one go on
        // this thread, so no other upgrade can slip in between.
        std::lock_guard<std::mutex> lock(mutex_);
        id = next_id_++;
        Conn& c = conns_[id];
        c.wsi = wsi;
        c.peer = peer;
        per_ip_[peer]++;
        pre_hello_++;
      }
      pss->id = id;
      // A bounded kernel send buffer: frames a peer does not read pile up in our queue, where
      // the session sees them (latest pose wins, slow-reader timeout), instead of hiding in an
      // autotuned multi-megabyte socket buffer as added latency.
      if (options_.socket_send_buffer > 0) {
        const int fd = static_cast<int>(lws_get_socket_fd(wsi));
        const int size = options_.socket_send_buffer;
        if (fd >= 0) setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &size, sizeof(size));
      }
      // A small unsent queue in the kernel: the socket is writable again only when the frame
      // before has nearly left, so on a slow link the next frame waits in the session (latest
      // pose wins) and the send delay tells the link's rate (session/link_rate.h).
      if (options_.notsent_lowat > 0) {
        const int fd = static_cast<int>(lws_get_socket_fd(wsi));
        const int bytes = options_.notsent_lowat;
        if (fd >= 0) setsockopt(fd, IPPROTO_TCP, TCP_NOTSENT_LOWAT, &bytes, sizeof(bytes));
      }
      handler_.on_open(id);
      return 0;
    }
    case LWS_CALLBACK_RECEIVE: {
      if (!pss || !pss->id) return -1;
      MessageKind kind = MessageKind::binary;
      std::string message;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        auto it = conns_.find(pss->id);
        if (it == conns_.end()) return -1;
        if (!take_fragment(wsi, it->second, in, len, kind, message)) return 0;
      }
      handler_.on_message(pss->id, kind, std::move(message));
      return 0;
    }
    case LWS_CALLBACK_SERVER_WRITEABLE:
      if (!pss || !pss->id) return 0;
      return write_some(wsi, pss->id);
    case LWS_CALLBACK_EVENT_WAIT_CANCELLED: {
      apply_pending_tls();
      // Another thread queued work: ask for writable callbacks (only legal on this thread).
      std::vector<ConnId> dirty;
      std::vector<std::pair<lws*, int>> arm;  // connections whose close timeout starts now
      std::vector<lws*> wake;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        dirty.swap(dirty_);
        std::sort(dirty.begin(), dirty.end());
        dirty.erase(std::unique(dirty.begin(), dirty.end()), dirty.end());
        for (ConnId id : dirty) {
          auto it = conns_.find(id);
          if (it == conns_.end()) continue;
          Conn& c = it->second;
          if (c.closing && !c.close_armed) {
            c.close_armed = true;
            arm.emplace_back(c.wsi, (c.grace_ms + 999) / 1000);
          }
          wake.push_back(c.wsi);
        }
      }
      for (auto& [w, secs] : arm) lws_set_timeout(w, PENDING_TIMEOUT_USER_OK, secs);
      for (lws* w : wake) lws_callback_on_writable(w);
      return 0;
    }
    case LWS_CALLBACK_CLOSED: {
      if (!pss || !pss->id) return 0;
      const ConnId id = pss->id;
      pss->id = 0;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        auto it = conns_.find(id);
        if (it != conns_.end()) {
          if (!it->second.said_hello) pre_hello_--;
          auto ip = per_ip_.find(it->second.peer);
          if (ip != per_ip_.end() && --ip->second <= 0) per_ip_.erase(ip);
          conns_.erase(it);
        }
      }
      handler_.on_close(id);
      return 0;
    }
    default:
      return 0;
  }
}

bool Transport::take_fragment(lws* wsi, Conn& c, const void* in, std::size_t len, MessageKind& kind,
                              std::string& message) {
  if (c.rx_oversize) return false;  // already reported; nothing more is read (below)
  const bool first = lws_is_first_fragment(wsi) != 0;
  const bool final = lws_is_final_fragment(wsi) != 0;
  if (first && c.rx.empty()) c.rx_binary = lws_frame_is_binary(wsi) != 0;
  // What the frame header declared and is still to come counts now, not once it has arrived:
  // a frame declaring a gigabyte is refused at its first bytes (issue 22 finding 9).
  const std::size_t declared = c.rx.size() + len + lws_remaining_packet_payload(wsi);
  if (declared > options_.max_message_bytes) {
    c.rx_oversize = true;
    std::string().swap(c.rx);
    // Stop reading this socket: the session answers with an Error and closes (the close's
    // grace timeout ends a peer that does not read it).
    lws_rx_flow_control(wsi, 0);
    kind = MessageKind::oversize;
    return true;
  }
  c.rx.append(static_cast<const char*>(in), len);
  if (!final) return false;
  kind = c.rx_binary ? MessageKind::binary : MessageKind::text;
  message.swap(c.rx);
  return true;
}

int Transport::write_some(lws* wsi, ConnId id) {
  bool sent_counted = false;
  bool more = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = conns_.find(id);
    if (it == conns_.end()) return -1;
    Conn& c = it->second;
    if (c.queue.empty()) {
      // Once the close frame is lws's, a later writable callback must not close again: lws would
      // then skip the closing handshake and shut the socket down at once, and the peer's answer
      // (its close frame, or messages it sent meanwhile) would meet a closed socket and draw an
      // RST, which can make the peer drop the Error and the close frame unread (a page then saw
      // close code 1006 and no reason; docs/history/fuzzing_and_soak.md, "The closing handshake").
      if (!c.closing || c.close_sent) return 0;
      c.close_sent = true;
      // Everything (including the final Error) is written: close with a normal close frame.
      static const char kBye[] = "bye";
      lws_close_reason(wsi, LWS_CLOSE_STATUS_NORMAL, reinterpret_cast<unsigned char*>(const_cast<char*>(kBye)), 3);
      return -1;
    }
    Outgoing& m = c.queue.front();
    const std::size_t size = m.buf.size() - LWS_PRE;
    const std::size_t chunk = std::min(kFragmentBytes, size - m.offset);
    const bool first = m.offset == 0;
    const bool last = m.offset + chunk == size;
    // lws_write needs LWS_PRE writable bytes before the data: for later fragments those are
    // payload bytes already sent, which may be overwritten.
    const int n = lws_write(wsi, m.buf.data() + LWS_PRE + m.offset, chunk,
                            static_cast<lws_write_protocol>(lws_write_ws_flags(LWS_WRITE_BINARY, first, last)));
    if (n < 0) return -1;
    m.offset += chunk;
    if (last) {
      sent_counted = m.counted;
      c.queue.pop_front();
    }
    more = !c.queue.empty() || c.closing;
  }
  if (more) lws_callback_on_writable(wsi);
  if (sent_counted) handler_.on_sent(id, socket_sample(wsi));
  return 0;
}

}  // namespace catgs::server
