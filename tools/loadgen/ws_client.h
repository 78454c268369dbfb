// A small blocking WebSocket client over a raw TCP socket (RFC 6455, client side, no
// extensions), optionally over TLS (wss://, OpenSSL). Made for tests and load generation: besides
// normal use it can send malformed frames, stop reading, and drop the TCP connection without a
// close frame. Not thread-safe: one thread per client.
#pragma once

#include <cstdint>
#include <string>

struct ssl_st;      // OpenSSL's SSL
struct ssl_ctx_st;  // OpenSSL's SSL_CTX
struct x509_st;     // OpenSSL's X509

namespace catgs::loadgen {

// SHA-256 of `cert` (DER), lower-case hex ("" for null): which certificate a server presented.
std::string certificate_sha256(x509_st* cert);

class WsClient {
 public:
  WsClient() = default;
  ~WsClient();
  WsClient(const WsClient&) = delete;
  WsClient& operator=(const WsClient&) = delete;

  // Connects to host:port (IPv4 literal or name) and performs the HTTP upgrade for `path`,
  // asking for subprotocol `protocol` (empty: none). Throws std::runtime_error on failure or
  // when the server does not answer 101 within `timeout_ms`.
  // `receive_buffer` > 0 sets SO_RCVBUF before connecting (a small TCP window: a slow reader).
  void connect(const std::string& host, int port, const std::string& path, const std::string& protocol,
               int timeout_ms = 5000, int receive_buffer = 0);
  bool connected() const { return fd_ >= 0; }
  // Before connect(): speak TLS (wss://). The server's certificate is NOT verified (test and
  // load clients meet self-signed certificates); peer_certificate_sha256() says which one came.
  void use_tls(bool on) { tls_ = on; }
  // SHA-256 of the server's certificate (DER, lower-case hex) after a TLS connect; "" otherwise.
  std::string peer_certificate_sha256() const;

  // Sends one complete binary / text message (a single masked frame). Throws on socket errors.
  void send_binary(const std::string& payload);
  void send_text(const std::string& payload);
  // Sends arbitrary bytes on the socket (e.g. a broken frame).
  void send_raw(const std::string& bytes);

  enum class Recv { message, timeout, closed };
  // Waits up to `timeout_ms` for one complete message (fragments reassembled; pings answered).
  // `closed` when the server closed (close frame or EOF) or the socket failed.
  Recv recv(std::string& payload, bool& binary, int timeout_ms);

  // The status code of the server's close frame once recv() returned `closed` for one (RFC 6455
  // sec. 7.1.5); 0 before, or when the connection ended without a close frame.
  int close_code() const { return close_code_; }
  // Whether the server ended the TCP connection (EOF or reset) within `timeout_ms`, with nothing
  // unread before it. A server that sent its close frame must wait for ours (RFC 6455 sec. 7.1.1):
  // tests check it does not hang up first. Plain TCP only (false under TLS).
  bool peer_hung_up(int timeout_ms);

  // Sends a close frame and closes the socket.
  void close();
  // Closes the TCP connection at once, without a WebSocket close frame (RST via SO_LINGER 0).
  void close_abrupt();

 private:
  void send_frame(int opcode, const std::string& payload);
  void write_all(const char* data, std::size_t size);
  // The TLS handshake on the connected socket. Throws std::runtime_error.
  void start_tls(int timeout_ms);
  // Reads what is there within `timeout_ms` into rx: > 0 bytes read, 0 timeout, < 0 closed.
  long read_some(std::string& rx, int timeout_ms);
  void close_socket();
  // Tries to parse one frame from rx_; returns false when incomplete.
  bool parse_frame(bool& fin, int& opcode, std::string& payload);

  int fd_ = -1;
  int close_code_ = 0;
  bool tls_ = false;
  ssl_ctx_st* ssl_ctx_ = nullptr;
  ssl_st* ssl_ = nullptr;
  std::string rx_;       // bytes received, not yet parsed
  std::string message_;  // fragments of the message being reassembled
  int message_opcode_ = 0;
  std::uint32_t mask_state_ = 0x9e3779b9u;
};

}  // namespace catgs::loadgen
