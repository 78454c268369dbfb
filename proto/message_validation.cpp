#include "proto/message_validation.h"

#include <algorithm>
#include <cmath>

namespace catgs::server {

std::optional<Violation> check_viewport(std::uint32_t width, std::uint32_t height, const ViewportLimit& limit,
                                        Viewport& out) {
  auto ok = [](std::uint32_t v) { return v >= kMinViewport && v <= kMaxViewport; };
  const std::string size = "viewport " + std::to_string(width) + "x" + std::to_string(height);
  if (!ok(width) || !ok(height)) return Violation{pb::ERROR_INVALID_ARGUMENT, size + " outside 16..4096"};
  // Both sides are at most 4096 here: the products fit 64 bits.
  const std::uint64_t pixels = std::uint64_t{width} * height;
  const std::uint64_t max_pixels = static_cast<std::uint64_t>(limit.width) * static_cast<std::uint64_t>(limit.height);
  const std::uint32_t max_side = static_cast<std::uint32_t>(std::max(limit.width, limit.height));
  if (pixels > max_pixels || std::max(width, height) > max_side)
    return Violation{pb::ERROR_INVALID_ARGUMENT, size + " larger than the server's --max-viewport " +
                                                     std::to_string(limit.width) + "x" + std::to_string(limit.height)};
  // H.264 4:2:0 needs even sizes.
  out.width = static_cast<int>(width & ~1u);
  out.height = static_cast<int>(height & ~1u);
  return std::nullopt;
}

std::optional<Violation> check_hello(const pb::Hello& hello, const ViewportLimit& limit, Viewport& out) {
  if (hello.protocol_version() != 1)
    return Violation{pb::ERROR_PROTOCOL,
                     "unsupported protocol_version " + std::to_string(hello.protocol_version()) + " (server speaks 1)"};
  return check_viewport(hello.viewport_width(), hello.viewport_height(), limit, out);
}

std::optional<Violation> check_pose(const pb::Pose& pose, CameraPose& out) {
  if (!pose.has_position() || !pose.has_orientation())
    return Violation{pb::ERROR_INVALID_ARGUMENT, "Pose needs position and orientation"};
  const auto& p = pose.position();
  const auto& q = pose.orientation();
  const double values[] = {p.x(),
                           p.y(),
                           p.z(),
                           q.w(),
                           q.x(),
                           q.y(),
                           q.z(),
                           pose.vertical_fov_deg(),
                           pose.client_time_ms(),
                           pose.shown_latency_ms(),
                           pose.received_ms()};
  for (double v : values)
    if (!std::isfinite(v)) return Violation{pb::ERROR_INVALID_ARGUMENT, "Pose has NaN or Inf"};
  // Positions beyond float range would turn into Inf in the renderer.
  for (double v : {p.x(), p.y(), p.z()})
    if (std::fabs(v) > kMaxPoseComponent) return Violation{pb::ERROR_INVALID_ARGUMENT, "Pose position too large"};
  // A component past 1e154 would overflow the squared norm to Inf and normalise to zero.
  for (double v : {q.w(), q.x(), q.y(), q.z()})
    if (std::fabs(v) > kMaxPoseComponent)
      return Violation{pb::ERROR_INVALID_ARGUMENT, "Pose orientation component beyond 1e30"};
  const double norm = std::sqrt(q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z());
  if (!(norm > 1e-6)) return Violation{pb::ERROR_INVALID_ARGUMENT, "Pose orientation is a zero quaternion"};
  if (!(pose.vertical_fov_deg() > kMinFovDeg && pose.vertical_fov_deg() < kMaxFovDeg))
    return Violation{pb::ERROR_INVALID_ARGUMENT,
                     "vertical_fov_deg " + std::to_string(pose.vertical_fov_deg()) + " outside (1, 170)"};
  if (!(pose.shown_latency_ms() >= 0 && pose.shown_latency_ms() <= kMaxShownLatencyMs))
    return Violation{pb::ERROR_INVALID_ARGUMENT,
                     "shown_latency_ms " + std::to_string(pose.shown_latency_ms()) + " outside 0..3600000"};
  if (!(pose.display_hz() == 0 || (pose.display_hz() >= kMinDisplayHz && pose.display_hz() <= kMaxDisplayHz)))
    return Violation{pb::ERROR_INVALID_ARGUMENT,
                     "display_hz " + std::to_string(pose.display_hz()) + " is neither 0 nor in 24..240"};
  if (!(pose.received_ms() >= 0 && pose.received_ms() <= kMaxClientTimeMs))
    return Violation{pb::ERROR_INVALID_ARGUMENT,
                     "received_ms " + std::to_string(pose.received_ms()) + " outside 0..1e15"};
  out.position = glm::vec3(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
  out.orientation = glm::quat(static_cast<float>(q.w() / norm), static_cast<float>(q.x() / norm),
                              static_cast<float>(q.y() / norm), static_cast<float>(q.z() / norm));
  out.vertical_fov_deg = static_cast<float>(pose.vertical_fov_deg());
  return std::nullopt;
}

namespace {

std::optional<Violation> check_eye(const char* name, const pb::EyeView& eye, EyePose& out) {
  const std::string who = std::string("Pose ") + name + ": ";
  // The eye's pose under check_pose's rules (a Pose of it alone, with a field of view that passes).
  pb::Pose as_pose;
  *as_pose.mutable_position() = eye.position();
  *as_pose.mutable_orientation() = eye.orientation();
  as_pose.set_vertical_fov_deg(90.0);
  if (!eye.has_position() || !eye.has_orientation())
    return Violation{pb::ERROR_INVALID_ARGUMENT, who + "needs position and orientation"};
  CameraPose p;
  if (auto bad = check_pose(as_pose, p)) return Violation{bad->code, who + bad->reason};
  const double angles[] = {eye.angle_left(), eye.angle_right(), eye.angle_up(), eye.angle_down()};
  for (double a : angles)
    if (!(std::fabs(a) <= kMaxEyeAngle))  // NaN fails too
      return Violation{pb::ERROR_INVALID_ARGUMENT, who + "an angle is NaN, Inf or beyond 1.5 rad"};
  if (!(eye.angle_left() < eye.angle_right()) || !(eye.angle_down() < eye.angle_up()))
    return Violation{pb::ERROR_INVALID_ARGUMENT, who + "needs angle_left < angle_right and angle_down < angle_up"};
  out.position = p.position;
  out.orientation = p.orientation;
  out.angle_left = static_cast<float>(eye.angle_left());
  out.angle_right = static_cast<float>(eye.angle_right());
  out.angle_up = static_cast<float>(eye.angle_up());
  out.angle_down = static_cast<float>(eye.angle_down());
  return std::nullopt;
}

}  // namespace

std::optional<Violation> check_stereo(const pb::Pose& pose, std::optional<StereoPose>& out) {
  out.reset();
  if (!pose.has_left_eye() && !pose.has_right_eye()) return std::nullopt;
  if (!pose.has_left_eye() || !pose.has_right_eye())
    return Violation{pb::ERROR_INVALID_ARGUMENT, "Pose has one eye: a stereo pose needs left_eye and right_eye"};
  StereoPose s;
  if (auto bad = check_eye("left_eye", pose.left_eye(), s.left)) return bad;
  if (auto bad = check_eye("right_eye", pose.right_eye(), s.right)) return bad;
  out = s;
  return std::nullopt;
}

std::optional<Violation> check_quality(const pb::Quality& quality) {
  const std::uint32_t b = quality.max_bitrate_kbps();
  if (b != 0 && (b < kMinBitrateKbps || b > kMaxBitrateKbps))
    return Violation{pb::ERROR_INVALID_ARGUMENT, "Quality.max_bitrate_kbps " + std::to_string(b) + " outside 0 or " +
                                                     std::to_string(kMinBitrateKbps) + ".." +
                                                     std::to_string(kMaxBitrateKbps)};
  return std::nullopt;
}

std::optional<Violation> check_depth_request(const pb::DepthRequest& request,
                                             const std::optional<CameraPose>& last_pose, const Viewport& viewport,
                                             DepthQuery& out) {
  if (request.has_pose()) {
    if (auto bad = check_pose(request.pose(), out.pose))
      return Violation{bad->code, "DepthRequest pose: " + bad->reason};
  } else if (last_pose) {
    out.pose = *last_pose;
  } else {
    return Violation{pb::ERROR_INVALID_ARGUMENT, "DepthRequest without a pose before any Pose"};
  }
  if (request.width() == 0 && request.height() == 0) {
    out.width = viewport.width;
    out.height = viewport.height;
  } else if (request.width() < 1 || request.width() > kMaxViewport || request.height() < 1 ||
             request.height() > kMaxViewport) {
    return Violation{pb::ERROR_INVALID_ARGUMENT, "DepthRequest view " + std::to_string(request.width()) + "x" +
                                                     std::to_string(request.height()) + " outside 1..4096"};
  } else {
    out.width = static_cast<int>(request.width());
    out.height = static_cast<int>(request.height());
  }
  if (!std::isfinite(request.x()) || !std::isfinite(request.y()))
    return Violation{pb::ERROR_INVALID_ARGUMENT, "DepthRequest pixel is NaN or Inf"};
  // Written so that the message shows the pixel and the view the client should have used.
  if (!(request.x() >= 0 && request.x() < out.width && request.y() >= 0 && request.y() < out.height))
    return Violation{pb::ERROR_INVALID_ARGUMENT,
                     "DepthRequest pixel (" + std::to_string(request.x()) + ", " + std::to_string(request.y()) +
                         ") is outside the " + std::to_string(out.width) + "x" + std::to_string(out.height) + " view"};
  out.x = request.x();
  out.y = request.y();
  return std::nullopt;
}

namespace {

Violation export_violation(const std::string& reason) {
  return Violation{pb::ERROR_INVALID_ARGUMENT, "ExportVideoRequest: " + reason};
}

// Pose k of the path as a Pose message, so that it is held to check_pose's rules.
pb::Pose path_pose(const pb::ExportVideoRequest& request, int k) {
  const float* f = request.path().data() + static_cast<std::ptrdiff_t>(k) * kExportFloatsPerPose;
  pb::Pose pose;
  pose.mutable_position()->set_x(f[1]);
  pose.mutable_position()->set_y(f[2]);
  pose.mutable_position()->set_z(f[3]);
  pose.mutable_orientation()->set_w(f[4]);
  pose.mutable_orientation()->set_x(f[5]);
  pose.mutable_orientation()->set_y(f[6]);
  pose.mutable_orientation()->set_z(f[7]);
  pose.set_vertical_fov_deg(f[8]);
  return pose;
}

}  // namespace

std::optional<Violation> check_export_request(const pb::ExportVideoRequest& request, const ExportLimits& limits,
                                              ExportPlan& out) {
  const int floats = request.path_size();
  if (floats % kExportFloatsPerPose != 0)
    return export_violation("path has " + std::to_string(floats) + " floats, not 9 a pose");
  const int poses = floats / kExportFloatsPerPose;
  if (poses > limits.max_poses)
    return export_violation("a path of " + std::to_string(poses) + " poses is over the server's --export-max-poses " +
                            std::to_string(limits.max_poses));
  if (poses < 2) return export_violation("a path needs at least 2 poses, got " + std::to_string(poses));
  const std::uint32_t w = request.width(), h = request.height();
  const std::string size = std::to_string(w) + "x" + std::to_string(h);
  if (w < kMinViewport || w > kMaxViewport || h < kMinViewport || h > kMaxViewport)
    return export_violation("video size " + size + " outside 16..4096");
  if (w % 2 || h % 2) return export_violation("video size " + size + ": width and height must be even (4:2:0)");
  const std::uint64_t max_pixels = static_cast<std::uint64_t>(limits.max_width) * limits.max_height;
  if (std::uint64_t{w} * h > max_pixels ||
      std::max(w, h) > static_cast<std::uint32_t>(std::max(limits.max_width, limits.max_height)))
    return export_violation("video size " + size + " is over the server's --export-max-size " +
                            std::to_string(limits.max_width) + "x" + std::to_string(limits.max_height));
  if (request.fps() < 1 || request.fps() > static_cast<std::uint32_t>(limits.max_fps))
    return export_violation("fps " + std::to_string(request.fps()) + " outside 1..--export-max-fps " +
                            std::to_string(limits.max_fps));
  Pipeline pipeline = Pipeline::exact;
  if (!request.pipeline().empty()) {
    try {
      pipeline = parse_pipeline(request.pipeline());
    } catch (const std::exception&) {
      return export_violation("unknown pipeline '" + request.pipeline().substr(0, 32) + "' (vanilla, exact or catgs)");
    }
  }
  Trace path;
  path.reserve(static_cast<std::size_t>(poses));
  for (int k = 0; k < poses; ++k) {
    const float t = request.path(k * kExportFloatsPerPose);
    if (!std::isfinite(t)) return export_violation("pose " + std::to_string(k) + ": time is NaN or Inf");
    if (k > 0 && t < path.back().time_s) return export_violation("pose " + std::to_string(k) + ": time goes backwards");
    CameraPose pose;
    if (auto bad = check_pose(path_pose(request, k), pose))
      return export_violation("pose " + std::to_string(k) + ": " + bad->reason);
    path.push_back(TimedCamera{t, Camera::from_pose(pose.position, pose.orientation, pose.vertical_fov_deg,
                                                    static_cast<int>(w), static_cast<int>(h))});
  }
  const double span_s = path.back().time_s - path.front().time_s;
  if (span_s > limits.max_seconds)
    return export_violation("a path of " + std::to_string(span_s) + " s is over the server's --export-max-seconds " +
                            std::to_string(limits.max_seconds));
  const double t0 = path.front().time_s;
  for (TimedCamera& c : path) c.time_s -= t0;
  out.frames = resample_trace(path, request.fps());
  out.export_id = request.export_id();
  out.width = static_cast<int>(w);
  out.height = static_cast<int>(h);
  out.fps = static_cast<int>(request.fps());
  out.pipeline = pipeline;
  out.duration_s = static_cast<double>(out.frames.size()) / out.fps;
  return std::nullopt;
}

}  // namespace catgs::server
