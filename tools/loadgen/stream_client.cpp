#include "loadgen/stream_client.h"

#include <chrono>
#include <stdexcept>

#include "proto/message_validation.h"

namespace catgs::loadgen {

pb::Pose pose_from_camera(const Camera& camera, std::uint32_t sequence, double client_time_ms) {
  pb::Pose p;
  p.set_sequence(sequence);
  p.set_client_time_ms(client_time_ms);
  const glm::vec3 c = camera.position();
  const glm::quat q = camera.orientation();
  p.mutable_position()->set_x(c.x);
  p.mutable_position()->set_y(c.y);
  p.mutable_position()->set_z(c.z);
  p.mutable_orientation()->set_w(q.w);
  p.mutable_orientation()->set_x(q.x);
  p.mutable_orientation()->set_y(q.y);
  p.mutable_orientation()->set_z(q.z);
  p.set_vertical_fov_deg(camera.vertical_fov_deg());
  return p;
}

pb::Pose stereo_pose_from_camera(const Camera& head, const HeadsetOptics& optics, std::uint32_t sequence,
                                 double client_time_ms) {
  pb::Pose p = pose_from_camera(head, sequence, client_time_ms);
  const glm::quat q = head.orientation();
  const glm::vec3 right = glm::mat3_cast(q)[0];  // the head's x axis in the world
  auto eye = [&](pb::EyeView* e, float side) {
    const glm::vec3 c = head.position() + side * 0.5f * optics.ipd * right;
    e->mutable_position()->set_x(c.x);
    e->mutable_position()->set_y(c.y);
    e->mutable_position()->set_z(c.z);
    *e->mutable_orientation() = p.orientation();
    // The right eye's frustum mirrors the left's (its nose side is its left).
    e->set_angle_left(side < 0 ? optics.angle_left : -optics.angle_right);
    e->set_angle_right(side < 0 ? optics.angle_right : -optics.angle_left);
    e->set_angle_up(optics.angle_up);
    e->set_angle_down(optics.angle_down);
  };
  eye(p.mutable_left_eye(), -1.0f);
  eye(p.mutable_right_eye(), 1.0f);
  return p;
}

Camera eye_camera_from_pose(const pb::Pose& pose, bool right, int eye_width, int height) {
  std::optional<server::StereoPose> eyes;
  if (auto bad = server::check_stereo(pose, eyes)) throw std::invalid_argument(bad->reason);
  if (!eyes) throw std::invalid_argument("the pose has no eyes");
  const server::EyePose& e = right ? eyes->right : eyes->left;
  return Camera::from_frustum(e.position, e.orientation, e.angle_left, e.angle_right, e.angle_up, e.angle_down,
                              eye_width, height);
}

Camera camera_from_pose(const pb::Pose& pose, int width, int height) {
  server::CameraPose cp;
  if (auto bad = server::check_pose(pose, cp)) throw std::invalid_argument(bad->reason);
  return Camera::from_pose(cp.position, cp.orientation, cp.vertical_fov_deg, width, height);
}

Refused::Refused(pb::Error error)
    : std::runtime_error("server refused Hello: " + pb::ErrorCode_Name(error.code()) + ": " + error.reason()),
      error_(std::move(error)) {}

void StreamClient::connect(int port, const std::string& host, int timeout_ms, int receive_buffer) {
  ws_.connect(host, port, "/ws", "catgs.v1", timeout_ms, receive_buffer);
}

void StreamClient::send(const pb::ClientMessage& message) {
  std::string bytes;
  message.SerializeToString(&bytes);
  ws_.send_binary(bytes);
}

void StreamClient::send_pose(const pb::Pose& pose) {
  pb::ClientMessage m;
  *m.mutable_pose() = pose;
  send(m);
}

pb::Welcome StreamClient::hello(int width, int height, const std::string& token, int timeout_ms,
                                const std::string& scene, std::vector<pb::ServerMessage>* before_welcome,
                                bool load_progress, bool offer_av1) {
  pb::ClientMessage m;
  pb::Hello* h = m.mutable_hello();
  h->set_protocol_version(1);
  h->set_viewport_width(static_cast<std::uint32_t>(width));
  h->set_viewport_height(static_cast<std::uint32_t>(height));
  if (offer_av1) h->add_codecs(pb::CODEC_AV1);
  h->add_codecs(pb::CODEC_H264);
  h->set_token(token);
  h->set_client_name("catgs-loadgen");
  h->set_scene(scene);
  h->set_load_progress(load_progress);
  send(m);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline) {
    auto msg = recv(100);
    if (!msg) continue;
    if (msg->has_welcome()) return msg->welcome();
    if (msg->has_error()) throw Refused(msg->error());
    if (before_welcome) before_welcome->push_back(*msg);
  }
  throw std::runtime_error("no Welcome within " + std::to_string(timeout_ms) + " ms");
}

std::optional<pb::ServerMessage> StreamClient::recv(int timeout_ms) {
  std::string bytes;
  bool binary = false;
  const auto r = ws_.recv(bytes, binary, timeout_ms);
  if (r == WsClient::Recv::timeout) return std::nullopt;
  if (r == WsClient::Recv::closed) {
    closed_ = true;
    throw std::runtime_error("connection closed");
  }
  pb::ServerMessage m;
  if (!binary || !m.ParseFromString(bytes)) throw std::runtime_error("unparsable server message");
  return m;
}

}  // namespace catgs::loadgen
