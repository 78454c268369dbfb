#include "loadgen/ws_client.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstring>
#include <stdexcept>

#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>

namespace catgs::loadgen {

namespace {

using Clock = std::chrono::steady_clock;

// Rounded up: a poll for the truncated time would wake before the deadline and leave a part of a
// millisecond to spin through with poll(0) (issue 92: that spin was most of the client's cores).
int remaining_ms(Clock::time_point deadline) {
  const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - Clock::now());
  return left.count() < 0 ? 0 : static_cast<int>(left.count());
}

}  // namespace

WsClient::~WsClient() { close_socket(); }

void WsClient::close_socket() {
  if (ssl_) SSL_free(ssl_);
  if (ssl_ctx_) SSL_CTX_free(ssl_ctx_);
  ssl_ = nullptr;
  ssl_ctx_ = nullptr;
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

void WsClient::start_tls(int timeout_ms) {
  // OpenSSL writes with send() without MSG_NOSIGNAL: a server that closed first would kill a
  // test or load process with SIGPIPE instead of failing the write.
  std::signal(SIGPIPE, SIG_IGN);
  ssl_ctx_ = SSL_CTX_new(TLS_client_method());
  if (!ssl_ctx_) throw std::runtime_error("ws: no TLS context");
  SSL_CTX_set_verify(ssl_ctx_, SSL_VERIFY_NONE, nullptr);  // ws_client.h: self-signed certificates
  // Without AUTO_RETRY a read that only finds TLS 1.3 session tickets returns instead of blocking
  // past the caller's timeout (read_some).
  SSL_CTX_clear_mode(ssl_ctx_, SSL_MODE_AUTO_RETRY);
  ssl_ = SSL_new(ssl_ctx_);
  if (!ssl_ || SSL_set_fd(ssl_, fd_) != 1) throw std::runtime_error("ws: no TLS connection object");
  // The handshake blocks: bound it by the connect timeout.
  timeval tv{timeout_ms / 1000, (timeout_ms % 1000) * 1000};
  setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  const int ok = SSL_connect(ssl_);
  timeval none{0, 0};
  setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &none, sizeof(none));
  if (ok != 1) {
    char why[256] = "no answer";
    if (const unsigned long e = ERR_get_error()) ERR_error_string_n(e, why, sizeof(why));
    ERR_clear_error();
    throw std::runtime_error(std::string("ws: TLS handshake failed: ") + why);
  }
}

std::string certificate_sha256(x509_st* cert) {
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int n = 0;
  if (!cert || X509_digest(cert, EVP_sha256(), md, &n) != 1) return "";
  static const char kHex[] = "0123456789abcdef";
  std::string hex;
  for (unsigned int i = 0; i < n; ++i) {
    hex.push_back(kHex[md[i] >> 4]);
    hex.push_back(kHex[md[i] & 15]);
  }
  return hex;
}

std::string WsClient::peer_certificate_sha256() const {
  if (!ssl_) return "";
  X509* cert = SSL_get1_peer_certificate(ssl_);
  const std::string sha = certificate_sha256(cert);
  X509_free(cert);
  return sha;
}

long WsClient::read_some(std::string& rx, int timeout_ms) {
  // Bytes OpenSSL has already decrypted do not make the socket readable.
  if (!ssl_ || SSL_pending(ssl_) == 0) {
    pollfd p{fd_, POLLIN, 0};
    const int r = ::poll(&p, 1, timeout_ms);
    if (r == 0) return 0;
    if (r < 0) return errno == EINTR ? 0 : -1;
  }
  char buf[65536];
  long n = 0;
  if (ssl_) {
    n = SSL_read(ssl_, buf, sizeof(buf));
    if (n <= 0) {
      const int e = SSL_get_error(ssl_, static_cast<int>(n));
      ERR_clear_error();
      return e == SSL_ERROR_WANT_READ ? 0 : -1;  // WANT_READ: a record without data (a ticket)
    }
  } else {
    n = ::recv(fd_, buf, sizeof(buf), 0);
    if (n <= 0) return -1;
  }
  rx.append(buf, static_cast<std::size_t>(n));
  return n;
}

void WsClient::connect(const std::string& host, int port, const std::string& path, const std::string& protocol,
                       int timeout_ms, int receive_buffer) {
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  if (getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &res) != 0 || !res)
    throw std::runtime_error("ws: cannot resolve " + host);
  fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd_ >= 0 && receive_buffer > 0) setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &receive_buffer, sizeof(receive_buffer));
  const int rc = ::connect(fd_, res->ai_addr, res->ai_addrlen);
  freeaddrinfo(res);
  if (fd_ < 0 || rc != 0) {
    const std::string err = std::strerror(errno);
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    throw std::runtime_error("ws: connect to " + host + ":" + std::to_string(port) + ": " + err);
  }
  int one = 1;
  setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
  if (tls_) {
    try {
      start_tls(timeout_ms);
    } catch (const std::exception&) {
      close_socket();
      throw;
    }
  }
  std::string req = "GET " + path + " HTTP/1.1\r\nHost: " + host + ":" + std::to_string(port) +
                    "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n";
  if (!protocol.empty()) req += "Sec-WebSocket-Protocol: " + protocol + "\r\n";
  req += "\r\n";
  write_all(req.data(), req.size());

  const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  std::string head;
  for (;;) {
    const auto end = head.find("\r\n\r\n");
    if (end != std::string::npos) {
      rx_ = head.substr(end + 4);  // frames may follow the response in the same read
      head.resize(end);
      break;
    }
    const long n = read_some(head, remaining_ms(deadline));
    if (n < 0) throw std::runtime_error("ws: connection closed during handshake");
    if (n == 0 && remaining_ms(deadline) == 0)
      throw std::runtime_error("ws: no handshake answer within " + std::to_string(timeout_ms) + " ms");
  }
  if (head.compare(0, 12, "HTTP/1.1 101") != 0)
    throw std::runtime_error("ws: upgrade refused: " + head.substr(0, head.find("\r\n")));
}

void WsClient::write_all(const char* data, std::size_t size) {
  if (fd_ < 0) throw std::runtime_error("ws: not connected");
  while (size > 0) {
    if (ssl_) {
      const int n = SSL_write(ssl_, data, static_cast<int>(std::min<std::size_t>(size, 1 << 30)));
      if (n <= 0) {
        ERR_clear_error();
        throw std::runtime_error("ws: TLS write failed");
      }
      data += n;
      size -= static_cast<std::size_t>(n);
      continue;
    }
    const ssize_t n = ::send(fd_, data, size, MSG_NOSIGNAL);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw std::runtime_error(std::string("ws: send: ") + std::strerror(errno));
    }
    data += n;
    size -= static_cast<std::size_t>(n);
  }
}

void WsClient::send_frame(int opcode, const std::string& payload) {
  std::string f;
  f.push_back(static_cast<char>(0x80 | opcode));  // FIN + opcode
  const std::size_t n = payload.size();
  if (n < 126) {
    f.push_back(static_cast<char>(0x80 | n));
  } else if (n < 65536) {
    f.push_back(static_cast<char>(0x80 | 126));
    f.push_back(static_cast<char>(n >> 8));
    f.push_back(static_cast<char>(n & 0xff));
  } else {
    f.push_back(static_cast<char>(0x80 | 127));
    for (int i = 7; i >= 0; --i) f.push_back(static_cast<char>((n >> (8 * i)) & 0xff));
  }
  // Clients must mask (RFC 6455 5.3); a cheap xorshift is enough for a test client.
  mask_state_ ^= mask_state_ << 13;
  mask_state_ ^= mask_state_ >> 17;
  mask_state_ ^= mask_state_ << 5;
  char mask[4];
  std::memcpy(mask, &mask_state_, 4);
  f.append(mask, 4);
  const std::size_t start = f.size();
  f += payload;
  for (std::size_t i = 0; i < n; ++i) f[start + i] = static_cast<char>(f[start + i] ^ mask[i & 3]);
  write_all(f.data(), f.size());
}

void WsClient::send_binary(const std::string& payload) { send_frame(0x2, payload); }
void WsClient::send_text(const std::string& payload) { send_frame(0x1, payload); }
void WsClient::send_raw(const std::string& bytes) { write_all(bytes.data(), bytes.size()); }

bool WsClient::parse_frame(bool& fin, int& opcode, std::string& payload) {
  if (rx_.size() < 2) return false;
  const auto b0 = static_cast<unsigned char>(rx_[0]);
  const auto b1 = static_cast<unsigned char>(rx_[1]);
  fin = (b0 & 0x80) != 0;
  opcode = b0 & 0x0f;
  std::size_t len = b1 & 0x7f, pos = 2;
  if (len == 126) {
    if (rx_.size() < 4) return false;
    len = (static_cast<std::size_t>(static_cast<unsigned char>(rx_[2])) << 8) | static_cast<unsigned char>(rx_[3]);
    pos = 4;
  } else if (len == 127) {
    if (rx_.size() < 10) return false;
    len = 0;
    for (int i = 0; i < 8; ++i) len = (len << 8) | static_cast<unsigned char>(rx_[2 + static_cast<std::size_t>(i)]);
    pos = 10;
  }
  const bool masked = (b1 & 0x80) != 0;  // servers do not mask, but accept it
  char mask[4] = {0, 0, 0, 0};
  if (masked) {
    if (rx_.size() < pos + 4) return false;
    std::memcpy(mask, rx_.data() + pos, 4);
    pos += 4;
  }
  if (rx_.size() < pos + len) return false;
  payload.assign(rx_, pos, len);
  if (masked)
    for (std::size_t i = 0; i < len; ++i) payload[i] = static_cast<char>(payload[i] ^ mask[i & 3]);
  rx_.erase(0, pos + len);
  return true;
}

WsClient::Recv WsClient::recv(std::string& payload, bool& binary, int timeout_ms) {
  if (fd_ < 0) return Recv::closed;
  const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  for (;;) {
    bool fin = false;
    int opcode = 0;
    std::string data;
    while (parse_frame(fin, opcode, data)) {
      if (opcode == 0x8) {  // close frame: its status code first, when it has one
        if (data.size() >= 2)
          close_code_ = (static_cast<unsigned char>(data[0]) << 8) | static_cast<unsigned char>(data[1]);
        return Recv::closed;
      }
      if (opcode == 0x9) {  // ping -> pong
        send_frame(0xA, data);
        continue;
      }
      if (opcode == 0xA) continue;
      if (opcode != 0x0) {
        message_opcode_ = opcode;
        message_.clear();
      }
      message_ += data;
      if (fin) {
        payload.swap(message_);
        message_.clear();
        binary = message_opcode_ == 0x2;
        return Recv::message;
      }
    }
    const long n = read_some(rx_, remaining_ms(deadline));
    if (n < 0) return Recv::closed;
    if (n == 0 && remaining_ms(deadline) == 0) return Recv::timeout;
  }
}

bool WsClient::peer_hung_up(int timeout_ms) {
  if (fd_ < 0 || ssl_ || !rx_.empty()) return false;
  pollfd p{fd_, POLLIN, 0};
  if (::poll(&p, 1, timeout_ms) <= 0) return false;
  char c;
  const ssize_t n = ::recv(fd_, &c, 1, MSG_PEEK | MSG_DONTWAIT);
  return n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR);
}

void WsClient::close() {
  if (fd_ < 0) return;
  try {
    send_frame(0x8, std::string("\x03\xe8", 2));  // 1000 normal closure
  } catch (const std::exception&) {}
  if (ssl_) SSL_shutdown(ssl_);  // close_notify; the answer is not awaited
  close_socket();
}

void WsClient::close_abrupt() {
  if (fd_ < 0) return;
  linger l{1, 0};  // RST instead of an orderly FIN: the rudest disconnect TCP allows
  setsockopt(fd_, SOL_SOCKET, SO_LINGER, &l, sizeof(l));
  close_socket();
}

}  // namespace catgs::loadgen
