// One catgs-loadgen session: connect, Hello, replay a camera trace as timed poses, receive (and
// optionally decode) the frames, measure. Blocking; run one per thread.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "scene/gaussian_model.h"
#include "camera/trace.h"
#include "catgs_stream.pb.h"
#include "loadgen/load_report.h"
#include "loadgen/recording.h"
#include "loadgen/stream_client.h"
#include "loadgen/trace_cache.h"

namespace catgs::loadgen {

// The trace a session replays, by spec, at width x height:
//   "orbit"          a 360 degree orbit in 10 s at the distance of Welcome's initial pose,
//                    about Welcome's orbit centre and up (the viewer's orbit) when it sends them
//                    (scene_scale > 0), else about the scene's robust bounds (with `scene`) or
//                    Welcome's bounds
//   "real:C.json"    an INRIA cameras.json path moved onto the scene (fit_trace_to_scene, 0.5 s
//                    per view); needs `scene`
//   "cameras:C.json" the scene's own cameras, interpolated as they are (0.5 s per view)
//   anything else    our trace file (trace.h), rescaled
// Sampled at 120 Hz. Throws std::invalid_argument for "real:" without a scene, and what the
// readers throw for bad files.
Trace make_load_trace(const std::string& spec, const GaussianModel* scene, const ::catgs::stream::v1::Welcome& welcome,
                      int width, int height);

// The trace's camera at time t_s (seconds), looping: the sample at or just before
// t_s mod duration. `trace` must not be empty.
const Camera& camera_at(const Trace& trace, double t_s);

// Counters every session of a run updates as it goes, for the progress line.
struct Progress {
  std::atomic<int> open{0};      // sessions with a Welcome, not yet ended
  std::atomic<int> refused{0};   // Hello answered with Error
  std::atomic<int> failed{0};    // ended with errors (cannot connect, lost connection, server Error)
  std::atomic<int> finished{0};  // sessions whose thread is done, however they ended
  std::atomic<std::uint64_t> frames{0};
  std::atomic<std::uint64_t> poses{0};
};

struct LoadSessionConfig {
  int index = 0;  // session number (report only)
  std::string host = "127.0.0.1";
  int port = 8080;
  bool tls = false;  // wss:// (WsClient::use_tls)
  int width = 1280, height = 720;
  std::string token;
  std::string scene_name;       // Hello.scene: a name from the server's GET /scenes; "" its first scene
  std::string trace = "orbit";  // make_load_trace spec
  // The run's traces, shared by its sessions so each is made once (trace_cache.h); null: each
  // session makes its own.
  std::shared_ptr<TraceCache> traces;
  std::shared_ptr<const GaussianModel> scene;  // optional; needed by "real:" traces
  // The reference checks' scene: `scene` with its level of detail (lod/lod_build.h, built as the
  // server builds it), so a frame is compared with the reference drawn at the bound the server
  // drew it at (FrameTimings.lod_error_px; 0: the leaves, which are `scene` bit for bit). Null:
  // `scene` itself, every reference at full detail.
  std::shared_ptr<const GaussianModel> reference_scene;
  double offset_s = 0;        // start this far into the trace
  double arrive_after_s = 0;  // connect this long after the run starts (visitors arriving in turn)
  double rate_hz = 60;        // poses per second; 0: closed loop (`depth` poses outstanding)
  int depth = 1;
  double seconds = 10;     // how long poses are sent
  bool decode = false;     // decode every frame (latency then ends at the decoded picture)
  bool offer_av1 = false;  // Hello.codecs lists AV1 (--av1): the server may stream it
  int warmup_frames = 5;   // frames left out of latency and server statistics
  double warmup_s = 0;     // frames of poses sent in the first warmup_s seconds left out too
  bool timeline = false;   // record every frame (SessionResult::timeline; the JSON's "timeline")
  bool receipts = true;    // each Pose carries the newest frame's receipt (Pose.received_ms)
  // Receipts also for frames read after the client was away (--receipts 2), as clients before
  // issue 64 sent them: a late read then looks like a queue on the link.
  bool late_receipts = false;
  double stale_ms = 100;   // a frame later than this after its pose counts as stale
  double drain_ms = 1000;  // after the last pose, wait this long at most for its frame
  // Reference check (implies decode): every check_every-th frame is compared with the CPU
  // reference render (exact pipeline, black background) of the pose it answers, over
  // `reference_scene` at the frame's LOD bound, else `scene` (one of them required). 0: off. The CPU render blocks this session's thread: latency and FPS of a
  // checking run are not the server's.
  int check_every = 0;
  double check_min_psnr = 30;  // dB; frames below count in SessionResult::check_failures
  // A busy client (--read-stall-ms A-B, issue 64): after reading what has arrived, the session's
  // thread stalls for a random time in [min, max] ms before it reads (and sends poses) again, as
  // a page whose main thread is busy does. 0: never stalls.
  int read_stall_min_ms = 0, read_stall_max_ms = 0;
  // The camera stops (--still-s S, issue 64): after `seconds` of poses the session sends no more
  // and reads on for still_s seconds, decoding every frame; the picture shown 1 s and 3 s after
  // the last pose, and at the end, is compared with the CPU reference render of the pose it
  // answers (SessionResult::still_psnr_db; needs `scene`). 0: off.
  double still_s = 0;
  // The shown-picture measure (issue 91): record the session into this folder (recording.h:
  // the stream, every frame's arrival and pose, the poses, the trace). "": no recording. H.264
  // only (with offer_av1 the session fails).
  std::string record_dir;
  // An emulated link (recording.h): each pose sent is the trace's pose half the round trip ago;
  // with a rate, a Quality caps the stream at kLinkRateShare of it, as the server's link
  // controller would settle below a real link's rate.
  LinkEmulation link;
  // A headset (--stereo, issue 94): every pose is a stereo pose (stream_client.h) of the trace's
  // camera turned by kHeadTurn, and width x height is the stream's whole size, both eyes.
  bool stereo = false;
  HeadsetOptics optics;
  // With `stereo`: one eye's view alone (--mono-eye), a mono Pose of the left eye (its position,
  // the head's orientation, a vertical field of view of the eye's up-to-down span) at width x
  // height: what one eye costs the server, against which a stereo frame is measured.
  bool mono_eye = false;
  Progress* progress = nullptr;  // optional; outlives the session
};

// A headset's head turns as the visitor looks around (issue 94 asks for turns up to 200 degrees
// a second): the trace's camera yawed about its own up axis by amplitude sin(2 pi t / period),
// whose fastest is 2 pi amplitude / period (25 degrees in 0.8 s: 196 degrees a second).
struct HeadTurn {
  double amplitude_deg = 25.0, period_s = 0.8;
};
inline constexpr HeadTurn kHeadTurn{};
// The left eye of a head as a mono camera (LoadSessionConfig::mono_eye): ipd / 2 to the head's
// left, the head's orientation, a symmetric vertical field of view of the eye's span.
Camera left_eye_view(const Camera& head, const HeadsetOptics& optics);
// The head at time t_s: `trace_camera` yawed by the turn.
Camera turned_head(const Camera& trace_camera, double t_s, const HeadTurn& turn = kHeadTurn);

// The share of an emulated link's rate the stream is capped at (Quality.max_bitrate_kbps).
inline constexpr double kLinkRateShare = 0.8;

// The page camera's orbit for a session that opened with `welcome` (web_client/viewer/camera.js
// OrbitCamera.fromWelcome, setPose): how far ahead of the camera its target stays while a path
// plays (the first view's distance to the target, world units) and its scene scale
// (SessionRecording::plane_distance and scene_scale).
struct PageOrbit {
  double distance = 1, scene_scale = 1;
};
PageOrbit page_orbit(const ::catgs::stream::v1::Welcome& welcome);

// Runs one session. Throws std::invalid_argument for check_every > 0 without a scene. Otherwise
// never throws: a refused Hello sets SessionResult::refused (and `refusal`); other failures are
// counted in SessionResult::errors (first_error names the first one).
SessionResult run_load_session(const LoadSessionConfig& config);

}  // namespace catgs::loadgen
