// A protocol-level client of catgs-server (catgs.stream.v1 over WebSocket): Hello/Welcome,
// poses built from catgs::Camera, typed server messages. Tests, load generation, benchmarks.
#pragma once

#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "catgs_stream.pb.h"
#include "loadgen/ws_client.h"

namespace catgs::loadgen {

namespace pb = ::catgs::stream::v1;

// The Pose message for `camera`: position(), orientation(), vertical_fov_deg().
pb::Pose pose_from_camera(const Camera& camera, std::uint32_t sequence, double client_time_ms);

// The camera the server renders for `pose` at width x height: the server's own validation and
// Camera::from_pose, so the result is bit-identical. Throws std::invalid_argument for a pose the
// server would reject.
Camera camera_from_pose(const pb::Pose& pose, int width, int height);

// The server answered Hello with Error: the session was refused (SERVER_FULL, UNAUTHORIZED,
// SHUTTING_DOWN, ...). `error` is the server's message, retry_after_ms included.
class Refused : public std::runtime_error {
 public:
  explicit Refused(pb::Error error);
  const pb::Error& error() const { return error_; }

 private:
  pb::Error error_;
};

class StreamClient {
 public:
  // Connects to ws://host:port/ws with subprotocol catgs.v1. Throws std::runtime_error.
  // `receive_buffer` > 0: SO_RCVBUF before connecting (see WsClient::connect).
  void connect(int port, const std::string& host = "127.0.0.1", int timeout_ms = 5000, int receive_buffer = 0);
  // Sends Hello and waits for Welcome. Throws Refused (a std::runtime_error naming the Error) if
  // the server refuses, std::runtime_error on timeout.
  // `scene`: Hello.scene (a name from GET /scenes; "" the server's first). `load_progress`: sets
  // Hello.load_progress (the server then sends LoadProgress while the scene loads).
  // `before_welcome`: when set, receives every message that came before Welcome, in order.
  // `offer_av1`: Hello.codecs lists AV1 before H.264 (the server may then stream AV1).
  pb::Welcome hello(int width, int height, const std::string& token = "", int timeout_ms = 10000,
                    const std::string& scene = "", std::vector<pb::ServerMessage>* before_welcome = nullptr,
                    bool load_progress = false, bool offer_av1 = false);
  // Sends one ClientMessage.
  void send(const pb::ClientMessage& message);
  void send_pose(const pb::Pose& pose);
  // The next server message within timeout_ms; nullopt on timeout. Throws std::runtime_error
  // when the connection closed (`closed()` then true) or the bytes do not parse.
  std::optional<pb::ServerMessage> recv(int timeout_ms);
  bool closed() const { return closed_; }
  WsClient& ws() { return ws_; }

 private:
  WsClient ws_;
  bool closed_ = false;
};

}  // namespace catgs::loadgen
