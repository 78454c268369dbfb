// A session's recording for the shown-picture measure (issue 91): what the visitor's screen had to
// show, and when. catgs-loadgen --record writes one folder a session; catgs-shown reads it, decodes
// the stream with libavcodec and scores, per display refresh, the newest frame the visitor had,
// re-projected as the page does, against the ideal render of where the visitor is then.
//
// A folder holds:
//   meta.json      the session: size, trace spec, the emulated link (round trip, rate), the page's
//                  re-projection plane distance (see plane_distance), the run's clock span
//   display.trace  the session's trace at its size (trace.h format): the visitor's pose at trace
//                  time t is camera_at(trace, t) (load_session.h)
//   poses.tsv      one line a pose sent: sequence, sent_ms, trace_s
//   frames.tsv     one line a frame received: sequence, pose_sequence, arrived_ms, key (0/1),
//                  width, height, lod_error_px, offset and bytes of its access unit in the stream,
//                  and the pose it shows where the server predicted one (Frame.shown_pose:
//                  px,py,pz,qw,qx,qy,qz,fov_deg; "-" where it shows its Pose), and its
//                  depth grid (Frame.depth_grid: cols,rows,cell_px,inverse_depth_max,codes in
//                  hex; "-" where it has none)
//   stream.h264    every frame's H.264 access unit (Annex B) in arrival order (an elementary
//                  stream, as FFmpeg's h264 demuxer reads it; catgs-shown decodes it with
//                  libavcodec)
// Times (sent_ms, arrived_ms) are milliseconds on the client's clock from the session's first
// pose. The emulated link (LinkEmulation) holds a pose for half the round trip before the server
// sees it, so the pose sent at time w is the trace's pose at w - rtt/2 (+ the session's offset):
// trace_s says which. The frames' half of the round trip and the link's rate are applied when
// scoring (visible_ms), so one run's frames could be scored on other links' return paths too.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "camera/trace.h"
#include "catgs_stream.pb.h"

namespace catgs::loadgen {

// A link between the visitor and the server, emulated inside the client (this kernel has no netem).
struct LinkEmulation {
  double rtt_ms = 0;     // round trip: poses wait half of it, frames the other half
  double rate_mbit = 0;  // the server-to-visitor rate, Mbit/s; 0: unlimited (loopback)
};

struct RecordedPose {
  std::uint32_t sequence = 0;
  double sent_ms = 0;  // when it left the client
  double trace_s = 0;  // the trace time of its camera (camera_at)
};

struct RecordedFrame {
  std::uint32_t sequence = 0, pose_sequence = 0;
  double arrived_ms = 0;  // when the client read it off the socket
  bool key = false;
  int width = 0, height = 0;
  float lod_error_px = 0;
  std::uint64_t offset = 0, bytes = 0;  // its access unit in stream.h264
  // Frame.shown_pose: position (3), camera-to-world quaternion (w, x, y, z), vertical fov in
  // degrees; empty where the frame shows its Pose.
  std::optional<std::array<double, 8>> shown_pose;
  // Frame.depth_grid as it came (proto/depth_grid_coding.h unpacks it); empty where none.
  std::optional<::catgs::stream::v1::DepthGrid> depth_grid;
};

struct SessionRecording {
  int width = 0, height = 0;
  std::string trace_spec;
  double offset_s = 0;  // the session's start in its trace
  double seconds = 0;   // how long poses were sent
  LinkEmulation link;
  // The page's re-projection plane while it plays a path: the orbit target stays this far ahead
  // of the camera along its forward axis (camera.js setPose keeps the distance to the target;
  // the first view's target is Welcome.orbit_centre), world units.
  double plane_distance = 1;
  // The page camera's scene scale (camera.js sceneScale: Welcome.scene_scale, else the bounds'
  // diagonal): planeDepthFor's fallback when the target is behind the shown frame's camera.
  double scene_scale = 1;
  Trace trace;
  std::vector<RecordedPose> poses;
  std::vector<RecordedFrame> frames;
  std::string stream;  // the access units, frames[i] at [offset, offset + bytes)
};

// When frame `k` is on the visitor's screen, ms on the recording's clock: read off the socket,
// then through the link's rate (a queue: a frame leaves after the one before it has, bytes x 8 /
// rate later) and half the round trip. The decode is not counted (a few ms in the page).
std::vector<double> visible_ms(const SessionRecording& recording);

// Writes `recording` into folder `dir` (made if absent). Throws std::runtime_error naming the file.
void write_recording(const SessionRecording& recording, const std::string& dir);
// Reads a folder written by write_recording. Throws std::runtime_error naming the file and line
// for a missing file, a malformed line, a count out of range (sizes beyond kMaxImageSide), a frame
// outside the stream or a pose it names not sent.
SessionRecording read_recording(const std::string& dir);

}  // namespace catgs::loadgen
