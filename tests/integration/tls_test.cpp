// Issue 22 (TLS): --tls-cert / --tls-key against the real server on loopback. Certificates are
// made by the test with the OpenSSL C API (self-signed, EC P-256), so no `openssl` tool is
// needed. The clients do not verify the server's certificate (it is self-signed); instead each
// test compares the certificate the server presented with the one it wrote (SHA-256 of the DER).
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <stdexcept>
#include <thread>

#include <lws_config.h>  // LWS_WITH_TLS: whether this libwebsockets can serve TLS at all
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>

#include "loadgen/stream_client.h"
#include "server_process.h"
#include "stream_checks.h"

namespace {

using namespace catgs;
using namespace catgs::loadgen;
using namespace catgs::itest;
using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

#if defined(LWS_WITH_TLS)
constexpr bool kLwsHasTls = true;
#else
constexpr bool kLwsHasTls = false;
#endif
#define SKIP_WITHOUT_LWS_TLS() \
  if (!kLwsHasTls) GTEST_SKIP() << "this libwebsockets is built without TLS (LWS_WITH_TLS unset in lws_config.h)"

// A self-signed certificate for CN=localhost with serial `serial`, and its key, as PEM files.
struct TestCert {
  std::string cert, key;  // paths
  std::string sha256;     // of the certificate
};

TestCert make_cert(const fs::path& dir, const std::string& name, long serial) {
  // EC P-256: a key in milliseconds (RSA 2048 takes a good fraction of a second on these cores).
  std::unique_ptr<EVP_PKEY, decltype(&EVP_PKEY_free)> key(EVP_EC_gen("P-256"), EVP_PKEY_free);
  std::unique_ptr<X509, decltype(&X509_free)> x(X509_new(), X509_free);
  if (!key || !x) throw std::runtime_error("OpenSSL: cannot make a key");
  X509_set_version(x.get(), 2);
  ASN1_INTEGER_set(X509_get_serialNumber(x.get()), serial);
  X509_gmtime_adj(X509_getm_notBefore(x.get()), -60);
  X509_gmtime_adj(X509_getm_notAfter(x.get()), 24 * 3600);
  X509_set_pubkey(x.get(), key.get());
  X509_NAME* subject = X509_get_subject_name(x.get());
  X509_NAME_add_entry_by_txt(subject, "CN", MBSTRING_ASC, reinterpret_cast<const unsigned char*>("localhost"), -1, -1,
                             0);
  X509_set_issuer_name(x.get(), subject);
  if (X509_sign(x.get(), key.get(), EVP_sha256()) <= 0) throw std::runtime_error("OpenSSL: cannot sign");
  TestCert t{(dir / (name + ".crt")).string(), (dir / (name + ".key")).string(), certificate_sha256(x.get())};
  FILE* f = std::fopen(t.cert.c_str(), "w");
  const bool cert_ok = f && PEM_write_X509(f, x.get()) == 1;
  if (f) std::fclose(f);
  f = std::fopen(t.key.c_str(), "w");
  const bool key_ok = f && PEM_write_PrivateKey(f, key.get(), nullptr, nullptr, 0, nullptr, nullptr) == 1;
  if (f) std::fclose(f);
  if (!cert_ok || !key_ok) throw std::runtime_error("cannot write " + t.cert + " / " + t.key);
  return t;
}

// Replaces `to`'s cert and key files by `from`'s contents the way an operator (or cert-manager)
// would: write beside, then rename over.
void install_files(const TestCert& from, const TestCert& to) {
  fs::copy_file(from.cert, to.cert + ".new", fs::copy_options::overwrite_existing);
  fs::copy_file(from.key, to.key + ".new", fs::copy_options::overwrite_existing);
  fs::rename(to.cert + ".new", to.cert);
  fs::rename(to.key + ".new", to.key);
}

// A temporary folder, removed with everything in it.
struct TempDir {
  fs::path path;
  TempDir() {
    char tmpl[] = "/tmp/catgs-tls-XXXXXX";
    if (!mkdtemp(tmpl)) throw std::runtime_error("mkdtemp failed");
    path = tmpl;
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

// One request over TLS to 127.0.0.1:port (certificate not verified: see the top). Returns the
// raw answer (head and body, "" when the handshake failed) once it is complete (Content-Length
// read, or the head of a 101), the server closed, or 5 s passed; `peer_sha256` gets the
// server's certificate.
std::string tls_request(int port, const std::string& request, std::string* peer_sha256 = nullptr) {
  const int fd = connect_loopback(port);
  if (fd < 0) return "";
  timeval tv{5, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  std::unique_ptr<SSL_CTX, decltype(&SSL_CTX_free)> ctx(SSL_CTX_new(TLS_client_method()), SSL_CTX_free);
  SSL_CTX_set_verify(ctx.get(), SSL_VERIFY_NONE, nullptr);
  std::unique_ptr<SSL, decltype(&SSL_free)> ssl(SSL_new(ctx.get()), SSL_free);
  SSL_set_fd(ssl.get(), fd);
  std::string resp;
  if (SSL_connect(ssl.get()) == 1) {
    if (peer_sha256) {
      X509* cert = SSL_get1_peer_certificate(ssl.get());
      *peer_sha256 = certificate_sha256(cert);
      X509_free(cert);
    }
    SSL_write(ssl.get(), request.data(), static_cast<int>(request.size()));
    const auto deadline = Clock::now() + std::chrono::seconds(5);
    std::smatch m;
    const std::regex length("\r\n[Cc]ontent-[Ll]ength: *([0-9]+)\r\n");
    while (Clock::now() < deadline) {
      const auto end = resp.find("\r\n\r\n");
      if (end != std::string::npos) {
        const std::string head = resp.substr(0, end + 2);
        if (head.compare(0, 12, "HTTP/1.1 101") == 0) break;
        if (std::regex_search(head, m, length) && resp.size() >= end + 4 + std::stoul(m[1])) break;
      }
      char buf[16384];
      const int n = SSL_read(ssl.get(), buf, sizeof(buf));
      if (n <= 0) break;
      resp.append(buf, static_cast<std::size_t>(n));
    }
  }
  ERR_clear_error();
  close(fd);
  return resp;
}

int status_of(const std::string& resp) {
  std::smatch m;
  return std::regex_search(resp, m, std::regex("^HTTP/1\\.[01] ([0-9]{3})")) ? std::stoi(m[1]) : -1;
}

std::string get_request(const std::string& path) {
  return "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
}

// The upgrade a browser on page `origin` sends to `host`.
std::string upgrade_request(const std::string& host, const std::string& origin) {
  return "GET /ws HTTP/1.1\r\nHost: " + host + "\r\nOrigin: " + origin +
         "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
         "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: catgs.v1\r\n\r\n";
}

std::vector<std::string> tls_args(const TestCert& c) {
  return server_args(kBiker, {"--tls-cert", c.cert, "--tls-key", c.key});
}

// A WSS session: connect, Hello at 160x120.
void open_session(StreamClient& c, int port) {
  c.ws().use_tls(true);
  c.connect(port);
  c.hello(160, 120);
}

// Sends pose `seq` of an orbit and waits for the Frame that shows it; true when it came with an
// encoded picture.
bool pose_gets_frame(StreamClient& c, std::uint32_t seq) {
  static const Trace orbit = biker_orbit(160, 120, 8);
  c.send_pose(pose_from_camera(orbit[seq % orbit.size()].camera, seq, now_ms()));
  auto m = wait_for(c, 20000,
                    [seq](const pb::ServerMessage& s) { return s.has_frame() && s.frame().pose_sequence() == seq; });
  return m && !m->frame().payload().empty();
}

// The certificate a new WSS connection is shown.
std::string new_connection_cert(int port) {
  WsClient ws;
  ws.use_tls(true);
  ws.connect("127.0.0.1", port, "/ws", "catgs.v1");
  return ws.peer_certificate_sha256();
}

bool wait_log(ServerProcess& server, const std::string& text, int timeout_ms = 5000) {
  const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  while (Clock::now() < deadline) {
    if (server.log().find(text) != std::string::npos) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return false;
}

// The server's start-up error for `args`, "" when it started.
std::string startup_error(const std::vector<std::string>& args) {
  try {
    ServerProcess server(args, 20000, ServerProcess::Until::probes);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

// ---------------------------------------------------------------------------------------------

// The page, /healthz, the Origin check and a whole session, over TLS on one port.
TEST(Tls, ServesPageHealthzAndSession) {
  SKIP_WITHOUT_LWS_TLS();
  TempDir dir;
  const TestCert a = make_cert(dir.path, "a", 1);
  ServerProcess server(tls_args(a));
  const int port = server.port();
  EXPECT_NE(server.log().find("listening on https://127.0.0.1:"), std::string::npos) << server.log();

  std::string seen;
  const std::string page = tls_request(port, get_request("/"), &seen);
  EXPECT_EQ(status_of(page), 200) << page.substr(0, 300);
  EXPECT_NE(page.find("<html"), std::string::npos) << "GET / over TLS did not serve the page";
  EXPECT_EQ(seen, a.sha256) << "not the certificate given with --tls-cert";
  const std::string health = tls_request(port, get_request("/healthz"));
  EXPECT_EQ(status_of(health), 200) << health;
  EXPECT_EQ(health.substr(health.find("\r\n\r\n") + 4), "ok\n");
  // The containers' HEALTHCHECK (catgs-server --probe) over https.
  const std::string probe =
      std::string(CATGS_SERVER_BIN) + " --probe https://127.0.0.1:" + std::to_string(port) + "/healthz >/dev/null 2>&1";
  EXPECT_EQ(std::system(probe.c_str()), 0) << probe;

  // The page's own https origin opens a WebSocket (the web client's wss:// URL); another
  // site's does not.
  const std::string host = "stream.example:" + std::to_string(port);
  EXPECT_EQ(status_of(tls_request(port, upgrade_request(host, "https://" + host))), 101);
  EXPECT_EQ(status_of(tls_request(port, upgrade_request(host, "https://evil.example"))), 403);

  StreamClient c;
  open_session(c, port);
  EXPECT_EQ(c.ws().peer_certificate_sha256(), a.sha256);
  for (std::uint32_t seq = 1; seq <= 2; ++seq) EXPECT_TRUE(pose_gets_frame(c, seq)) << "pose " << seq;
}

// The TLS port serves only TLS: plain HTTP gets no page (lws fails the handshake and closes).
TEST(Tls, PlainHttpOnTheTlsPortGetsNoPage) {
  SKIP_WITHOUT_LWS_TLS();
  TempDir dir;
  ServerProcess server(tls_args(make_cert(dir.path, "a", 1)));
  std::string body;
  const int status = http_get(server.port(), "/", body, 3000);
  EXPECT_NE(status, 200) << body.substr(0, 200);
  EXPECT_EQ(body.find("<html"), std::string::npos) << "the page went out unencrypted";
  StreamClient plain;  // ws:// on the same port
  EXPECT_THROW(plain.connect(server.port(), "127.0.0.1", 3000), std::runtime_error);
}

// Bad files stop the start with a message naming the file (before anything is served).
TEST(Tls, BadFilesFailAtStartNamingTheFile) {
  TempDir dir;
  const TestCert a = make_cert(dir.path, "a", 1);
  const TestCert b = make_cert(dir.path, "b", 2);
  const std::string junk = (dir.path / "junk.pem").string();
  std::ofstream(junk) << "not a key\n";
  const std::string missing = (dir.path / "missing.key").string();

  std::string e = startup_error(server_args(kBiker, {"--tls-cert", a.cert, "--tls-key", junk}));
  EXPECT_NE(e.find("--tls-key " + junk + ": no unencrypted PEM private key"), std::string::npos) << e;
  e = startup_error(server_args(kBiker, {"--tls-cert", a.cert, "--tls-key", missing}));
  EXPECT_NE(e.find("--tls-key " + missing + ": No such file"), std::string::npos) << e;
  e = startup_error(server_args(kBiker, {"--tls-cert", junk, "--tls-key", a.key}));
  EXPECT_NE(e.find("--tls-cert " + junk + ": no PEM certificate"), std::string::npos) << e;
  e = startup_error(server_args(kBiker, {"--tls-cert", a.cert, "--tls-key", b.key}));
  EXPECT_NE(e.find("--tls-key " + b.key + " does not belong to the certificate"), std::string::npos) << e;
  e = startup_error(server_args(kBiker, {"--tls-cert", a.cert}));
  EXPECT_NE(e.find("--tls-cert and --tls-key go together"), std::string::npos) << e;
}

// SIGHUP: new connections get the new certificate, an open session keeps streaming; bad new
// files are logged and the certificate in use stays.
TEST(Tls, SighupReloadsTheCertificateKeepingSessions) {
  SKIP_WITHOUT_LWS_TLS();
  TempDir dir;
  const TestCert live = make_cert(dir.path, "live", 1);
  const TestCert next = make_cert(dir.path, "next", 2);
  ASSERT_NE(live.sha256, next.sha256);
  ServerProcess server(tls_args(live));
  const int port = server.port();
  StreamClient session;
  open_session(session, port);
  ASSERT_TRUE(pose_gets_frame(session, 1));
  ASSERT_EQ(new_connection_cert(port), live.sha256);

  install_files(next, live);
  server.signal(SIGHUP);
  ASSERT_TRUE(wait_log(server, "tls: reloaded on SIGHUP: /CN=localhost, serial 02")) << server.log();
  EXPECT_EQ(new_connection_cert(port), next.sha256) << "a new connection still sees the old certificate";
  EXPECT_TRUE(pose_gets_frame(session, 2)) << "the open session stopped at the reload";
  EXPECT_EQ(session.ws().peer_certificate_sha256(), live.sha256);

  std::ofstream(live.key) << "not a key\n";
  server.signal(SIGHUP);
  ASSERT_TRUE(wait_log(server, "reload on SIGHUP failed")) << server.log();
  EXPECT_NE(server.log().find("--tls-key " + live.key), std::string::npos) << server.log();
  EXPECT_TRUE(server.running());
  EXPECT_EQ(new_connection_cert(port), next.sha256) << "a failed reload changed the certificate";
  EXPECT_TRUE(pose_gets_frame(session, 3));
}

// Without TLS, SIGHUP is logged and changes nothing (it used to end the process).
TEST(Tls, SighupWithoutTlsKeepsServing) {
  ServerProcess server(server_args(kBiker));
  server.signal(SIGHUP);
  ASSERT_TRUE(wait_log(server, "SIGHUP: nothing to reload")) << server.log();
  std::string body;
  EXPECT_EQ(http_get(server.port(), "/healthz", body), 200);
}

}  // namespace
