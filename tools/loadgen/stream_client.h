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

// A headset's optics (issue 94): the distance between its eyes and the left eye's frustum edges
// (radians from the forward axis, OpenXR's XrFovf; the right eye's is its mirror image). The
// defaults are a typical headset's, not a measured one's: 94 degrees each way, wider on the
// temple's side than the nose's and below than above (as headsets' canted lenses make them), and
// a 63 mm interpupillary distance, about the adult median.
struct HeadsetOptics {
  float ipd = 0.063f;  // world units (a scene in metres: metres)
  float angle_left = -0.942f, angle_right = 0.698f, angle_up = 0.768f, angle_down = -0.873f;
};

// The stereo Pose of a head at `head` (its position, orientation and field of view as
// pose_from_camera's): each eye ipd / 2 along the head's x axis (right), looking where the head
// looks, with `optics`' frusta.
pb::Pose stereo_pose_from_camera(const Camera& head, const HeadsetOptics& optics, std::uint32_t sequence,
                                 double client_time_ms);

// The camera the server renders for one eye of a stereo pose at eye_width x height: the server's
// own validation (check_stereo) and Camera::from_frustum. Throws std::invalid_argument for a pose
// the server would reject or one without eyes.
Camera eye_camera_from_pose(const pb::Pose& pose, bool right, int eye_width, int height);

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
