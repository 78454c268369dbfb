// The encoder policy: how a session's H.264 stream is sized for the network and for the host,
// instead of two fixed numbers (issue 35). Every default here comes from the rate-distortion-
// latency table that catgs-encode-bench measured (docs/history/encoding.md, "Encoder policy").
//
// Rate: a target bitrate by resolution and rate, target = bits_per_pixel x width x height x fps
// (at least min_kbps: a small picture needs more bits a pixel for the same look), used as the
// VBV's maximum rate of a capped CRF stream (crf the quality floor; EncoderConfig). A client's
// Quality.max_bitrate_kbps lowers it further, never raises it.
//
// Threads: x264's sliced threads cut one frame's encode time, so a lone session should get
// several; but the host's cores are shared by every session's encoder, so the threads a session
// gets are 2 x usable cores / live sessions (an encoder is busy only part of each frame
// interval, and more threads cost little more CPU a frame), at least what its viewport needs to
// keep 60 frames/s (needed_threads) and at most what it gains from (useful_threads). When
// sessions join, a session's next encoder gets fewer threads; when they leave, more (the server
// rebuilds an encoder only when its thread count should change, see should_rebuild()).
//
// Preset: x264's presets trade CPU time for quality at the same rate (what a step buys and costs:
// docs/history/encoding.md, "x264 presets by budget"). With --x264-preset auto a session's encoder takes the slowest preset of the ladder
// whose CPU time a frame, at the live session count and the nominal frame rate, fits the share of
// the host's cores the encoders may use (kEncoderCpuShare); as sessions join it steps down at
// once, as they leave it steps up after kGrowDelay (an IDR each time).
#pragma once

#include <chrono>
#include <string>

#include "encode/encoder.h"

namespace catgs::server {

struct EncoderPolicy {
  // --bitrate: < 0 (auto) target from bits_per_pixel; 0 (off) crf alone; > 0 that many kbit/s.
  int bitrate_kbps = -1;
  double bits_per_pixel = 0.09;  // --bits-per-pixel: auto's bits per pixel per frame
  // --bits-per-pixel auto: each scene and size probes its own (content_rate.h); bits_per_pixel
  // until its probe ends.
  bool content_rate = false;
  int min_kbps = 1500;               // auto's floor (small viewports)
  int crf = 23;                      // --crf: the quality floor
  int vbv_buffer_ms = 100;           // --vbv-ms: the VBV's size in ms of the target rate
  int intra_refresh_frames = 0;      // --intra-refresh N: refresh period in frames (0: off)
  int threads = 0;                   // --encoder-threads: > 0 fixed per session; 0 auto (above)
  std::string x264_preset = "auto";  // --x264-preset: "auto" (the ladder above) or one x264 preset
  // --x264-floor: the lowest ladder step (index into kPresetLadder) a session's stream may take
  // under "auto"; a visitor whose stream the cores could not encode at it is refused at the door
  // (cores_hold). -1 (off, the default): the ladder goes down to ultrafast and the door does not
  // count the encoders' cores.
  int floor_step = -1;
  int av1_speed = 10;  // --av1-speed: libaom's realtime cpu-used for AV1 streams
  // --av1: "auto" AV1 for a client that decodes it while the host affords it (use_av1), "on" for
  // every such client, "off" never (H.264 only).
  std::string av1 = "auto";
  int usable_cores = 1;  // the cores this process may use (cpu_quota.h)
};

// The VBV maximum rate in kbit/s for a width x height stream at `fps` frames/s; `client_max_kbps`
// (Quality.max_bitrate_kbps, 0: none) caps it. 0 means crf alone (policy.bitrate_kbps == 0 and
// no client cap).
int target_bitrate_kbps(const EncoderPolicy& policy, int width, int height, int fps, int client_max_kbps);

// The most sliced threads a width x height picture gains from (the measured table in
// docs/history/encoding.md: beyond it a frame's encode time no longer falls).
int useful_threads(int width, int height);

// The fewest sliced threads that encode a width x height frame within 3/4 of a 60 Hz frame
// interval (the measured table in docs/history/encoding.md): fewer and the session cannot hold 60 frames/s.
int needed_threads(int width, int height);

// x264 threads for one session's encoder while `live_sessions` sessions share the host.
int encoder_threads(const EncoderPolicy& policy, int width, int height, int live_sessions);

// The x264 presets the policy chooses from, cheapest first, with the CPU time a frame each takes
// relative to ultrafast's, the larger of the factors measured at 1080p and 720p; veryfast bought
// too little over superfast for its CPU to be a step. Between them, ultrafast with CABAC and
// deblocking turned back on: much of superfast's gain for less of its extra CPU (the rows that
// chose it: docs/history/encoding.md, "x264 presets by budget").
struct PresetStep {
  const char* name;
  double cpu_factor;
};
inline constexpr PresetStep kPresetLadder[] = {
    {"ultrafast", 1.0}, {"ultrafast+cabac+deblock", 1.4}, {"superfast", 2.3}};
inline constexpr int kPresetSteps = static_cast<int>(sizeof(kPresetLadder) / sizeof(kPresetLadder[0]));

// The share of the host's cores the sessions' encoders may use together: the rest render (the
// CPU core), convert, send and serve the sessions' strands.
inline constexpr double kEncoderCpuShare = 0.5;

// x264 ultrafast's CPU time for one width x height frame, ms: 7.7 ms a megapixel, whatever the
// thread count (the upper end of what docs/history/encoding.md, "Encoder policy", measured).
double ultrafast_cpu_ms(int width, int height);

// The ladder step (index into kPresetLadder) for one session's encoder at `fps` frames/s while
// `live_sessions` sessions share the host: the slowest whose CPU time fits the encoders' share of
// policy.usable_cores; 0 (ultrafast) when none does.
// Never below policy.floor_step.
int preset_step(const EncoderPolicy& policy, int width, int height, int fps, int live_sessions);

// Whether the encoders' share of the cores holds `live_sessions` width x height x264 streams at
// `fps` at the ladder's floor (policy.floor_step): the door's question for a visitor about to
// join (live_sessions counting it). True where no floor is set, or the preset is fixed.
bool cores_hold(const EncoderPolicy& policy, int width, int height, int fps, int live_sessions);

// The ladder step named `name` (kPresetLadder), or -1 for "off"; throws std::invalid_argument
// for any other name.
int ladder_step_named(const std::string& name);

// AV1 (libaom realtime at policy.av1_speed) above the ladder: its CPU time a frame relative to x264
// ultrafast's, the larger of the factors measured at 1080p and 720p on the H100 host, rounded up
// (docs/history/encoding.md, "AV1 where the host affords it").
inline constexpr double kAv1CpuFactor = 8.0;
// How much sooner a frame is done with 8 threads (row-based threads, a tile each) than with one:
// the smaller of the speed-ups measured at 1080p and 720p (same section); fewer threads are
// taken to gain linearly between 1 and that.
inline constexpr double kAv1EightThreadSpeedup = 4.7;
// An AV1 frame is expected (av1_frame_ms, a median) within this share of the frame interval, or
// the stream could not keep its frame rate: AV1's tail is long (key frames, busy views); a larger
// share lost frames in a ramp (docs/history/encoding.md, same section).
inline constexpr double kAv1FrameIntervalShare = 0.6;

// The wall time (ms) one AV1 frame of width x height is expected to take with `threads` threads:
// ultrafast_cpu_ms x kAv1CpuFactor over the threads' speed-up.
double av1_frame_ms(int width, int height, int threads);

// Whether a session's stream is AV1: its client decodes AV1 (Hello.codecs), the encoders are on
// the CPU (`cpu_encoder`: x264's host; NVENC hosts stream H.264 from the GPU), the link does not
// limit the stream (`link_limited`: AV1's rate cannot follow the link without a key frame, x264's
// can), and policy.av1 is "on", or "auto" where (1) AV1's CPU time at the live session count fits
// the encoders' share of the cores, as the ladder's steps do (preset_step), and (2) a frame, with
// the threads the session would get (encoder_threads), is expected within kAv1FrameIntervalShare
// of the frame interval (av1_frame_ms): on the H100 host's 16 cores at 60 frames/s 540p for up to
// 4 sessions, never 720p or 1080p, where x264 keeps the stream.
bool use_av1(const EncoderPolicy& policy, int width, int height, int fps, int live_sessions, bool client_decodes_av1,
             bool cpu_encoder, bool link_limited);

// The x264 preset for that session: policy.x264_preset unless it is "auto", else the ladder's.
std::string encoder_preset(const EncoderPolicy& policy, int width, int height, int fps, int live_sessions);

// Whether `name` is an x264 preset ("ultrafast" .. "placebo"), alone or with coding tools the
// preset leaves off turned back on: "ultrafast+cabac+deblock" (x264's CABAC entropy coder and
// its in-loop deblocking filter, the two tools ultrafast drops that cost the least CPU; x264's
// common/base.c presets, H.264 sections 9.3 and 8.7).
bool is_x264_preset(const std::string& name);

// The parts of such a name: the x264 preset, and the x264-params turning the tools on ("" for
// none; "cabac=1:deblock=1" for the example above). Throws std::invalid_argument for a name
// is_x264_preset refuses.
struct X264Preset {
  std::string preset;
  std::string params;
};
X264Preset parse_x264_preset(const std::string& name);

// The whole EncoderConfig for a session's encoder (size, fps, rate control, threads).
EncoderConfig encoder_config(const EncoderPolicy& policy, int width, int height, int fps, int live_sessions,
                             int client_max_kbps);

// Whether a running encoder with `current_threads` should be rebuilt for `wanted` threads. Fewer
// threads take effect at once (sessions joined: the cores are oversubscribed now); more only
// after `since_last_build` >= kGrowDelay (sessions left: no IDR storm while a tour group comes
// and goes). A rebuild costs an IDR. The same rule serves the preset's ladder step (a lower step
// is cheaper).
constexpr std::chrono::seconds kGrowDelay{5};
bool should_rebuild(int current_threads, int wanted, std::chrono::steady_clock::duration since_last_build);

}  // namespace catgs::server
