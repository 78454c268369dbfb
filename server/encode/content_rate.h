// Content-aware rate (issue 51, item 4): the stream's rate cap per scene and size from a short
// probe of the scene's own frames, instead of one bits-a-pixel figure for every scene.
//
// Why: a session's x264 stream is capped CRF (encoder.h): crf the quality floor, the policy's
// target bitrate the VBV's maximum rate. A simple scene (an object on a plain background) needs
// far less than the cap at that crf, and a busy one (a grass-covered city) far more, so one cap
// gives the busy scene a coarse picture while the simple one holds a peak allowance it never
// needs. The probe measures what crf wants for this scene at this size: the first kProbeFrames
// frames a session renders while its camera moves (a still camera's P frames cost next to
// nothing and say nothing about motion) are encoded a second time by an x264 encoder of the
// session's preset at the policy's crf with no cap; their mean bits a pixel, times
// kContentHeadroom (the VBV caps the rate, not each frame: a busy view and a quick turn go above
// the mean), clamped to [kContentMinBitsPerPixel, kContentMaxBitsPerPixel], is the cap's bits a
// pixel for that scene and size from then on (target_bitrate_kbps). The preset matters: at one
// crf, ultrafast takes several times superfast's bits (its crf scale is not the same picture;
// ContentRate.ProbeCountsPFramesAndSeesMotion prints both), so
// the probe codes as the stream it sizes does; a session on a cheaper step of the ladder later
// (more sessions) gets a somewhat coarser picture at that cap, as it would at a fixed one. The
// cost: the probing session's encode job encodes each of those frames twice (about 0.4 s of
// frames, once per scene and size while the server runs).
//
// The bounds: kContentMaxBitsPerPixel is the bandwidth bound for a 1080p60 stream
// (12 Mbit/s; 5.3 Mbit/s at 720p60, under its 6); kContentMinBitsPerPixel keeps a margin for
// views the probe did not see. What they give on real scenes, and why `auto` is not the default:
// docs/history/encoding.md, "Content-aware rate".
#pragma once

#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

#include "colour/yuv420.h"
#include "encode/encoder.h"
#include "encode/encoder_policy.h"

namespace catgs::server {

inline constexpr int kProbeFrames = 24;                   // moving frames a probe encodes (0.4 s at 60)
inline constexpr double kContentHeadroom = 1.5;           // cap / crf's mean rate
inline constexpr double kContentMinBitsPerPixel = 0.02;   // the cap's floor, bits a pixel a frame
inline constexpr double kContentMaxBitsPerPixel = 0.096;  // its ceiling: 12 Mbit/s at 1920x1080x60

// The cap's bits a pixel for content whose crf-alone stream takes `crf_bits_per_pixel`.
double content_bits_per_pixel(double crf_bits_per_pixel);

// One probe: an x264 encoder of `preset` (an x264 preset name, encoder_policy.h is_x264_preset)
// at policy.crf with no rate cap, fed a session's own pictures of width x height. Used by one
// thread at a time (the session's encode job).
class ContentRateProbe {
 public:
  // Opens the encoder (`threads` sliced threads, as the session's own). Throws what X264Encoder
  // throws.
  ContentRateProbe(const EncoderPolicy& policy, int width, int height, int threads, const std::string& preset);
  // Encodes one picture (BT.709 limited-range I420 of the probe's size); the first is an IDR and
  // is not counted (a stream is P frames after its first). No effect once done().
  void add(const Yuv420Planes& planes);
  bool done() const { return counted_ >= kProbeFrames; }
  // The mean bits a pixel of the counted frames (0 before any).
  double crf_bits_per_pixel() const;
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  std::unique_ptr<Encoder> encoder_;
  int width_, height_;
  int fed_ = 0, counted_ = 0;
  double bits_ = 0;
};

// The probed caps of one scene, by size: shared by the scene's sessions (thread-safe). One
// session at a time probes a size (claim); the others keep the policy's bits a pixel until the
// result is there.
class ContentRates {
 public:
  // The cap's bits a pixel at width x height, or 0 where no probe has ended.
  double bits_per_pixel(int width, int height) const;
  // Whether the caller should probe width x height: true for the first caller while the size has
  // no result and no other probe holds it. A holder ends with set() or release().
  bool claim(int width, int height);
  void release(int width, int height);
  // The probe's result (bits a pixel), which ends the claim.
  void set(int width, int height, double bits_per_pixel);

 private:
  mutable std::mutex mutex_;
  std::map<std::pair<int, int>, double> rates_;  // 0: claimed, not yet measured
};

}  // namespace catgs::server
