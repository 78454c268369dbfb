// Camera traces: timed sequences of poses; INRIA cameras.json, our trace file, generators.
#pragma once

#include <string>
#include <vector>

#include "base/bounds.h"
#include "camera/camera.h"

namespace catgs {

// One camera of a trace at time `time_s` (seconds from the start of the trace).
struct TimedCamera {
  double time_s = 0.0;
  Camera camera;
};

using Trace = std::vector<TimedCamera>;

// Reads an INRIA cameras.json (list of {id, img_name, width, height, position, rotation (3x3
// camera-to-world, rows), fx, fy}; principal point at the image centre), in file order. When
// width/height > 0 every view is rescaled to that size (the aspect ratio may change: fx and fy
// scale independently). Times are 0, 1, 2, ... seconds (sparse views have no clock).
// Throws std::runtime_error naming the file and the entry for malformed JSON or values.
std::vector<Camera> load_inria_cameras(const std::string& path, int width = 0, int height = 0);

// Interpolates sparse key views into a smooth trace sampled at `rate_hz`: centripetal Catmull-Rom
// for positions, slerp for orientations, linear intrinsics; consecutive keys are `seconds_per_view`
// apart. Returns (keys - 1) * seconds_per_view * rate_hz + 1 cameras. Throws std::invalid_argument
// for fewer than 2 keys or a non-positive rate.
Trace interpolate_views(const std::vector<Camera>& keys, double rate_hz, double seconds_per_view);

// The trace sampled on its own clock at `rate_hz`: cameras at t = t0 + k / rate_hz (t0 its first
// time) for every such t up to its last time, each between the two trace cameras around t:
// position linear, orientation slerp, intrinsics linear (the size of the earlier camera). A time
// within 1e-6 s of a trace camera's gives that camera as it is, so a trace recorded at
// rate_hz comes back unchanged. Used to render a trace to video at a chosen frame rate. Throws
// std::invalid_argument for an empty trace or a non-positive rate.
Trace resample_trace(const Trace& trace, double rate_hz);

// Synthetic generators around a scene's bounds (all cameras look at the bounds' centre unless
// said otherwise). `duration_s` seconds sampled at `rate_hz`; size `width` x `height`; vertical
// field of view `fov_deg`. Up is -y in camera (world up taken as `up`).
struct GeneratorParams {
  double duration_s = 5.0;
  double rate_hz = 120.0;
  int width = 1280, height = 720;
  float fov_deg = 60.0f;
  glm::vec3 up{0.0f, -1.0f, 0.0f};  // world up (3DGS captures are commonly y-down)
};
// Orbit: circle of radius `radius` around the centre at `height_offset` along up, `degrees` swept.
Trace make_orbit(const Bounds& bounds, float radius, float height_offset, float degrees, const GeneratorParams& params);
// Pan: camera at `eye` turns its yaw by `degrees` about up.
Trace make_pan(const glm::vec3& eye, const glm::vec3& look_at, float degrees, const GeneratorParams& params);
// Zoom: camera moves from distance `from` to `to` along the line to the centre.
Trace make_zoom(const Bounds& bounds, const glm::vec3& direction, float from, float to, const GeneratorParams& params);
// Fly-over: straight line from `start` to `end` at constant height, pitched down `pitch_deg`.
Trace make_flyover(const glm::vec3& start, const glm::vec3& end, float pitch_deg, const GeneratorParams& params);

// Our trace file (text, one camera per line; '#' starts a comment):
//   catgs-trace 1
//   <time_s> <px> <py> <pz> <qw> <qx> <qy> <qz> <fx> <fy> <cx> <cy> <width> <height>
// position = camera centre (world), q = camera-to-world rotation (OpenCV axes).
// Throws std::runtime_error naming the file and line on malformed input.
void write_trace(const Trace& trace, const std::string& path);
Trace read_trace(const std::string& path);

}  // namespace catgs
