// The encoder settings of one frame, decided in one call (docs/DESIGN.md "Data flow of a frame",
// the encode stage): the policy at the frame's size (with the scene's probed bits a pixel,
// content_rate.h), its VBV rate under the client's Quality and the link's cap, the VBV's size,
// whether it is AV1, the x264 ladder's step and preset, the sliced threads, and the whole
// EncoderConfig a rebuild would use. The frame pipeline (session/frame_pipeline.h) compares the
// result with its running encoder and applies it: a new VBV rate where x264 takes one, else a
// rebuild (an IDR); its content-rate probe encodes with the same preset and threads.
#pragma once

#include <string>

#include "encode/encoder.h"
#include "encode/encoder_policy.h"

namespace catgs::server {

// The stream's nominal frame rate: the browser's pose rate (its time base and the VBV's budget).
inline constexpr int kStreamFps = 60;
// The VBV's size while the link limits the stream (session/link_rate.h): two frames at
// kStreamFps, which the session's conversion of the cap by the measured frame rate makes two
// real frames' share.
inline constexpr int kLinkVbvMs = 2000 / kStreamFps;
// A refine frame's VBV (session/still_refine.h): x264 cannot switch its VBV off once on, so "no
// rate cap" is a rate and buffer no frame reaches (100 Mbit/s, a buffer of one second of it).
inline constexpr int kRefineKbps = 100000;
inline constexpr int kRefineVbvMs = 1000;

// The link's state when the frame is encoded (session/link_rate.h LinkRate, read on the
// session's strand): whether it limits the stream (with --link-control on), its cap on the wire
// (LinkRate::cap_kbps before the stream's ceiling, kbit/s), what the encoder sends over what it
// is asked (LinkRate::encoder_gain) and the frames a second it carries (LinkRate::frame_rate; 0:
// not measured yet).
struct LinkInputs {
  bool limiting = false;
  double cap_kbps = 0;
  double encoder_gain = 1.0;
  double frame_rate = 0;
};

// What a frame's encoder settings depend on.
struct FrameEncodeInputs {
  int width = 0, height = 0;         // the frame's size, pixels
  int client_max_kbps = 0;           // Quality.max_bitrate_kbps (0: none)
  LinkInputs link;                   // the link (a link that does not limit changes nothing)
  bool refine = false;               // the still view's refine frame (still_refine.h)
  int live_sessions = 1;             // sessions open on the server now (>= 1)
  bool av1_ok = false;               // the client decodes AV1 and the encoders are x264's CPU ones
  double probed_bits_per_pixel = 0;  // the scene's probed rate at this size (0: none yet)
  int fps = kStreamFps;              // the client's frames a second (Pose.display_hz, else kStreamFps)
};

// A frame's encoder settings.
struct FrameEncoding {
  EncoderPolicy policy;  // the server's, with the probed bits a pixel where it has one
  int rate_kbps = 0;     // the VBV's maximum rate after the client's and the link's caps (0: crf alone)
  int vbv_ms = 0;        // the VBV's size, ms of rate_kbps: kLinkVbvMs while the link limits
  bool av1 = false;      // the stream is AV1 (use_av1)
  int step = 0;          // the x264 ladder's step (preset_step; 0 for a fixed preset), kPresetSteps for AV1
  std::string preset;    // the x264 preset at that step (the content probe's too)
  int threads = 1;       // the encoder's sliced threads (encoder_threads)
  EncoderConfig config;  // everything a (re)build of the encoder takes
  // A refine frame on a capped stream: its encoder may lift the cap to kRefineKbps / kRefineVbvMs
  // for this frame alone (x264; others keep their rate).
  bool lift_cap = false;
  // The link's share (session/link_rate.h): the stream's ceiling on the wire, the policy's rate
  // under the client's cap times the frames a second the link carries over kStreamFps (at least
  // 10 frames' share; 0: crf alone), which the link's controller caps; and the encoder's rate cap
  // from the link (0: it does not limit): that cap over the same share, corrected by the
  // encoder's gain, so that a frame gets the cap's share of a second.
  int link_ceiling_kbps = 0;
  int link_kbps = 0;
};

// The one place a frame's encoder settings are decided. `policy`: the server's
// (--encoder-policy and friends); `in`: the frame's. Pure: the same inputs, the same settings.
FrameEncoding frame_encoding(const EncoderPolicy& policy, const FrameEncodeInputs& in);

// A client's Quality and the link's cap both lower the policy's rate, never raise it: the lower
// of the two where both are set (kbit/s; 0 for one that is not set).
int rate_cap_kbps(int client_kbps, int link_kbps);

}  // namespace catgs::server
