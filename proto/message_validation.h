// Checks of client messages against the protocol's rules (proto/catgs_stream.proto).
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include <glm/gtc/quaternion.hpp>
#include <glm/vec3.hpp>

#include "camera/trace.h"
#include "catgs_stream.pb.h"
#include "renderer/renderer.h"

namespace catgs::server {

namespace pb = ::catgs::stream::v1;

inline constexpr int kMinViewport = 16;
inline constexpr int kMaxViewport = 4096;
inline constexpr double kMinFovDeg = 1.0;            // exclusive
inline constexpr double kMaxFovDeg = 170.0;          // exclusive
inline constexpr double kMaxPoseComponent = 1e30;    // |position| and |quaternion| components
inline constexpr double kMaxShownLatencyMs = 3.6e6;  // Pose.shown_latency_ms: an hour
inline constexpr double kMaxClientTimeMs = 1e15;     // Pose.received_ms: a clock ms, 30,000 years
inline constexpr double kMaxEyeAngle = 1.5;          // |EyeView.angle_*|, radians (about 86 degrees)
inline constexpr double kMinDisplayHz = 24;          // Pose.display_hz, when set
inline constexpr double kMaxDisplayHz = 240;

// A protocol violation: the code and reason sent to the client in Error.
struct Violation {
  pb::ErrorCode code;
  std::string reason;
};

// A viewport after validation: even sizes in [16, 4096].
struct Viewport {
  int width = 0, height = 0;
};

// The server's largest viewport (--max-viewport WxH, default 3840x2160): a viewport fits when its
// pixel count is at most width x height and its longer side at most the longer of the two, so
// the same limit admits portrait and landscape clients.
struct ViewportLimit {
  int width = 3840, height = 2160;
};

// Validates a viewport (each side in [16, 4096], within `limit`) and rounds odd sizes down to
// even. Returns the violation (ERROR_INVALID_ARGUMENT) for an out-of-range size.
std::optional<Violation> check_viewport(std::uint32_t width, std::uint32_t height, const ViewportLimit& limit,
                                        Viewport& out);

// Validates Hello: protocol_version 1 (else ERROR_PROTOCOL) and the viewport.
std::optional<Violation> check_hello(const pb::Hello& hello, const ViewportLimit& limit, Viewport& out);

// A pose ready for the renderer (world units; camera-to-world rotation, OpenCV axes).
struct CameraPose {
  glm::vec3 position{0.0f};
  glm::quat orientation{1.0f, 0.0f, 0.0f, 0.0f};  // (w, x, y, z), unit
  float vertical_fov_deg = 60.0f;
};

// Validates Pose: position and orientation present, every number finite, position components
// and quaternion components within +-1e30 (so neither float conversion nor the squared norm
// overflows), quaternion not zero (it is normalised), fov in (1, 170) degrees, shown_latency_ms
// in [0, 3600000], received_ms in [0, 1e15], display_hz 0 or in [24, 240].
// ERROR_INVALID_ARGUMENT otherwise.
std::optional<Violation> check_pose(const pb::Pose& pose, CameraPose& out);

// A headset's eye ready for the renderer (EyeView; issue 94): its pose as CameraPose's, its
// frustum's edges in radians (Camera::from_frustum).
struct EyePose {
  glm::vec3 position{0.0f};
  glm::quat orientation{1.0f, 0.0f, 0.0f, 0.0f};  // (w, x, y, z), unit, camera-to-world, OpenCV axes
  float angle_left = -0.5f, angle_right = 0.5f, angle_up = 0.5f, angle_down = -0.5f;
};
struct StereoPose {
  EyePose left, right;
};

// Validates a Pose's eyes (left_eye, right_eye): neither (`out` reset), or both, each with a
// position and orientation checked as check_pose checks the head's, and angles finite, within
// +-kMaxEyeAngle, left < right and down < up. ERROR_INVALID_ARGUMENT otherwise, naming the eye.
std::optional<Violation> check_stereo(const pb::Pose& pose, std::optional<StereoPose>& out);

inline constexpr std::uint32_t kMinBitrateKbps = 100;
inline constexpr std::uint32_t kMaxBitrateKbps = 100000;

// Validates Quality: max_bitrate_kbps 0 (the server's default) or in [100, 100000] kbit/s.
// ERROR_INVALID_ARGUMENT otherwise.
std::optional<Violation> check_quality(const pb::Quality& quality);

// A DepthRequest ready for the probe (render_core/cpu/pixel_depth.h): the camera, its size and
// the pixel in continuous image coordinates.
struct DepthQuery {
  CameraPose pose;
  int width = 0, height = 0;  // pixels
  double x = 0, y = 0;        // x in [0, width), y in [0, height)
};

// Validates DepthRequest: its pose as check_pose (sequence and times ignored), or `last_pose`
// when it has none (a violation when that is empty too); its size, 1..4096 a side, or `viewport`
// when both are 0; x and y finite and inside the view. The violation's reason goes into
// DepthResult.error (the session goes on); its code is ERROR_INVALID_ARGUMENT.
std::optional<Violation> check_depth_request(const pb::DepthRequest& request,
                                             const std::optional<CameraPose>& last_pose, const Viewport& viewport,
                                             DepthQuery& out);

// The server's caps on ExportVideoRequest (--export-max-poses, --export-max-size WxH,
// --export-max-fps, --export-max-seconds, --export-max-concurrent; server/README.md "Video
// export" says why each default). Sizes as --max-viewport: pixel count and longer side.
struct ExportLimits {
  int max_poses = 1800;  // what one 64 KiB message holds (9 floats a pose, packed)
  int max_width = 3840, max_height = 2160;
  int max_fps = 60;
  int max_seconds = 600;   // of video: 36000 frames at 60 fps
  int max_concurrent = 1;  // exports rendering at once, server-wide
};

inline constexpr int kExportFloatsPerPose = 9;  // ExportVideoRequest.path

// A validated ExportVideoRequest: the frames to render, in order (the path sampled at fps on its
// clock, resample_trace; cameras of width x height, times from 0), and how.
struct ExportPlan {
  std::uint32_t export_id = 0;
  int width = 0, height = 0, fps = 0;
  Pipeline pipeline = Pipeline::exact;
  Trace frames;
  double duration_s = 0;  // frames.size() / fps
};

// Validates ExportVideoRequest against the protocol and `limits`: the pose count (checked before
// anything is parsed, so a million poses cost nothing), 9 floats a pose, each pose as check_pose
// (finite, a non-zero quaternion, fov in (1, 170)), times finite and never decreasing, a size
// 16..4096 a side, even, within max_width x max_height, fps 1..max_fps, the path's span at most
// max_seconds, the pipeline's name. Each reason names the cap's flag. Fills `out` (the resampled
// frames) only when it returns nullopt. Code ERROR_INVALID_ARGUMENT; the reason goes into
// ExportProgress.error (the session goes on).
std::optional<Violation> check_export_request(const pb::ExportVideoRequest& request, const ExportLimits& limits,
                                              ExportPlan& out);

}  // namespace catgs::server
