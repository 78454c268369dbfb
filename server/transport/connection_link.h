// What a session may do to its own connection: the part of the Transport a Session uses.
//
// Transport (transport.h) implements it over libwebsockets; the session fuzz target
// (tests/fuzz/fuzz_session.cpp) implements it in memory, so the protocol state machine runs
// without sockets or an lws service thread. Every call is thread-safe and names the connection
// by its ConnId; calls for a connection that is gone or closing are ignored (no error).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace catgs::server {

// Identifies one WebSocket connection for its lifetime (never reused).
using ConnId = std::uint64_t;

// What arrived in one complete WebSocket message (TransportHandler::on_message, transport.h).
enum class MessageKind { binary, text, oversize };

// TCP_INFO fields of a WebSocket's socket, read by the transport right after a frame's last byte
// was written (TransportHandler::on_sent). valid false: not a TCP socket, or the read failed.
struct SocketSample {
  bool valid = false;
  double rtt_ms = 0;              // smoothed round-trip time (tcpi_rtt)
  double min_rtt_ms = 0;          // the smallest seen on this connection (tcpi_min_rtt)
  double delivery_kbps = 0;       // the kernel's delivery-rate estimate (tcpi_delivery_rate)
  bool app_limited = true;        // that estimate was taken while the sender had nothing to send
  std::size_t notsent_bytes = 0;  // written by us, not yet sent by the kernel (tcpi_notsent_bytes)
  // Since the connection opened (0 where the kernel has not them): the time the socket had data
  // to send (tcpi_busy_time) and, of it, the time the receiver's advertised window held it back
  // (tcpi_rwnd_limited): a client that reads late, not the network.
  double busy_ms = 0;
  double rwnd_limited_ms = 0;
};

class ConnectionLink {
 public:
  virtual ~ConnectionLink() = default;
  // Queues one binary message (a serialized ServerMessage). `counted` messages (Frames) are
  // reported back once written (TransportHandler::on_sent, Session::post_sent).
  virtual void send(ConnId id, std::string bytes, bool counted) = 0;
  // Closes the connection after its queued messages are written (or after `grace_ms`).
  // `drop_queued` discards messages not yet started; `final_message`, when non-empty, is queued
  // last (the session's Error).
  virtual void close(ConnId id, std::string final_message, bool drop_queued, int grace_ms = 2000) = 0;
  // Messages queued for `id` and not yet fully written (0 for unknown ids).
  virtual std::size_t queued(ConnId id) const = 0;
  // The connection said a valid Hello: it no longer counts against --max-pre-hello.
  virtual void said_hello(ConnId id) = 0;
  // The client's address ("" for unknown ids).
  virtual std::string peer(ConnId id) const = 0;
  // Sets the socket's kernel send buffer (SO_SNDBUF, bytes; the kernel doubles it and keeps at
  // least its minimum): the bytes a connection may have sent but not acknowledged, plus unsent,
  // bound how deep a queue it can build in front of a slow link (session/link_rate.h).
  virtual void set_send_buffer(ConnId id, int bytes) = 0;
};

}  // namespace catgs::server
