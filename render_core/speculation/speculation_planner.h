// The host-side decisions of the catgs pipeline (paper sec. 3.1 "Motion Prediction", "Motion
// Adaptive Adjustment", sec. 3.2; docs/DESIGN.md "Speculation" 2), shared by the CPU reference
// (cpu::SpeculativeRenderer) and the CUDA renderer so both take the same key-frame / sub-frame
// decisions from the same poses.
//
// A group is a key frame plus up to W sub-frames. Per frame, a renderer:
//   1. observe(camera, t): feeds the motion predictor; true when the frame may be a sub-frame of
//      the open group (the group is open, fewer than W sub-frames were served, same intrinsics);
//   2. for a candidate sub-frame, checks every on-screen Gaussian still lies in its trail and
//      calls subframe_served(), or renders a key frame;
//   3. for a key frame: window_wanted() says whether to measure M at all; if so the renderer
//      measures M between the key camera and next_camera() and asks window_for(M); it pre-processes
//      over path(key, W), and while that list is over the render-list budget pre-processes again
//      with W = narrower_window(W) (W = 0: an exact frame); then it calls start_group(key, W).
//   4. with the cost model on (SpeculationParams::cost_model), record_cost() with the frame's
//      measured time once it is known.
#pragma once

#include <array>
#include <utility>
#include <vector>

#include "camera/camera.h"
#include "speculation/motion_predictor.h"
#include "speculation/speculation_params.h"

namespace catgs {

class SpeculationPlanner {
 public:
  // Throws std::invalid_argument for parameters validate() refuses (speculation_params.h).
  explicit SpeculationPlanner(const SpeculationParams& params = {});

  // New parameters (validated as above); closes the open group, keeps the motion history.
  void set_params(const SpeculationParams& params);
  const SpeculationParams& params() const { return params_; }

  // Adds the pose of `camera` at `time_s` (client clock, seconds) to the predictor. Returns true
  // when this frame may be served as a sub-frame of the open group: the group is open, the
  // intrinsics are the key frame's, and the pose is stamped within the window's span after the key
  // frame's, (W + 1/2) / F_target s (sub-frames are indexed by their time, not their count: a
  // server that skips a pose under load does not serve the trail's end for a later pose).
  bool observe(const Camera& camera, double time_s);

  // Seconds on the renderer's own clock for frames rendered without a time: 1 / F_target a call
  // (1 / 120 s with F_target = 0).
  double advance_clock() { return clock_s_ += params_.target_fps > 0.0 ? 1.0 / params_.target_fps : 1.0 / 120.0; }
  // 1 / F_target, seconds: the set F_target's, or the measured pose interval (F_target = 0; 1 / 120
  // s before two poses), at most kLongestPoseInterval_s.
  double frame_interval_s() const;
  // A pose clock slower than 30 Hz does not stretch a group's window: a sub-frame blends in its
  // key frame's depth order, which holds only while the camera has moved little; a slow
  // closed-loop client's windows spanned seconds of its path and its sub-frames fell far from
  // the exact render (docs/history/speculation.md, "A slow pose clock"). Slower clients' poses
  // fall outside the window and are key frames.
  static constexpr double kLongestPoseInterval_s = 1.0 / 30.0;

  // Whether a key frame may speculate at all (caching on, W_initial > 0, a motion history, no
  // backoff under way: SpeculationParams::backoff).
  bool window_wanted() const;
  // The predicted camera 1 / F_target after the newest pose, with `key`'s intrinsics (M's pair).
  Camera next_camera(const Camera& key) const { return predicted_camera(key, 1); }
  // W for the largest per-frame screen motion M (pixels): motion_adaptive_window(); with the cost
  // model on, the window up to that which the measured costs expect to repay most (0: none will,
  // and the frame starts a backoff as a poor group would). The model's yardstick, an exact frame's
  // cost, is measured by making a key frame exact (W = 0, no backoff) when it is not known or
  // was last measured over kExactRefresh frames ago (an exact frame costs less than a key frame
  // with a window, so the tail does not grow for it).
  int window_for(float max_motion_px);
  static constexpr int kExactRefresh = 120;
  // The window to plan a key frame with instead of `window`, whose list was over the render-list
  // budget (renderer.h RenderListBudget, issue 35): half of it, so a window's list shrinks
  // toward the exact list of W = 0, which the budget holds (in passes where it must). Both cores
  // narrow from the same counts, so they open the same groups.
  static int narrower_window(int window) { return window / 2; }
  // The key camera followed by the W predicted cameras at k / F_target, k = 1..W.
  std::vector<Camera> path(const Camera& key, int window) const;

  // A key frame was rendered with window W: a new group opens (W > 0) or none (W = 0). The group
  // it closes, if any, sets the backoff (SpeculationParams::backoff).
  void start_group(const Camera& key, int window);
  // The open group's key camera (start_group's `key`; the CUDA core's sub-frames take the LOD cut
  // at it, forward_model/lod.h).
  const Camera& key_camera() const { return key_camera_; }
  // The candidate sub-frame passed its containment check and was served from the caches.
  void subframe_served() { ++subframes_served_; }

  int window() const { return window_; }

  // The cost model's measurements (SpeculationParams::cost_model), milliseconds a frame.
  enum class FrameKind { exact, key, sub };
  // A frame's measured time: an exact frame (a key frame with W = 0), a key frame that opened a
  // group of `window` sub-frames, or a served sub-frame. Frames first tried as sub-frames and
  // rejected are not reported (their time mixes both). The first report of each kind is dropped
  // (a cold frame: its buffers were allocated in it); the rest are averaged, 1/8 a report.
  // Ignored with the cost model off.
  void record_cost(FrameKind kind, int window, double ms);
  // What the model expects a group of `window` sub-frames to cost a frame, against exact_ms():
  // (K(W) + n S + (1 - f) S) / (1 + n), with n = f W the sub-frames it is expected to serve (f:
  // the recent groups' served share), K(W) the key frame's measured cost at W (linear in W from the
  // nearest measured window when W itself was not), S a sub-frame's, and (1 - f) S the rejected
  // attempt that closes a group early (S counts as 0 before a sub-frame was served). Negative
  // while the exact or a key frame's cost is not measured yet.
  double expected_frame_ms(int window) const;
  double exact_ms() const { return cost_.exact_ms; }
  // The cost model's gain for the open group, as chosen: exact_ms() / expected_frame_ms(W) when
  // start_group opened it (0: no group, or the model had no figures).
  double predicted_gain() const { return predicted_gain_; }
  // The measured gain of the group the last start_group() closed, from its own reported times:
  // (1 + n) E / (K + S_1 + ... + S_n) for its key frame K and n served sub-frames S_i, E the
  // exact frame's average; 0 when none closed with its key frame's time known. Reading it
  // clears it, so each closed group is counted once.
  double take_measured_gain() { return std::exchange(measured_gain_, 0.0); }
  double served_share() const { return cost_.served_share; }
  // Sub-frames a group of `window` must serve to repay its key frame: (K(W) - E + S) / (E - S)
  // from the measured costs (more than W where sub-frames do not save); with the cost model off,
  // or before the costs are measured, the backoff's min_served scaled to W.
  double break_even_served(int window) const;

 private:
  Camera predicted_camera(const Camera& intrinsics, int frames_ahead) const;
  // The key frame now being planned closes an open group that served fewer than its break-even
  // count, with the backoff on: it renders in full, as the first frame of the backoff.
  bool closes_poor_group() const {
    return params_.backoff.frames > 0 && group_open_ && subframes_served_ < break_even_served(window_);
  }
  double key_ms(int window) const;
  // The backoff's cap after declined windows: 8x its frames, 32x with the cost model
  // (SpeculationBackoff; after a poor group it is 8x either way).
  int most_backoff() const { return (params_.cost_model ? 32 : 8) * params_.backoff.frames; }

  // Measured costs (exponential moving averages, ms) and the served share of recent groups.
  struct Costs {
    double exact_ms = 0.0, sub_ms = 0.0;
    std::array<double, kMaxWindow + 1> key_ms{};  // by window; 0: not measured
    double served_share = 1.0;                    // optimistic until a group closes
    std::array<int, 3> reports{};                 // by FrameKind: the first is dropped
    int frames_since_exact = 0;                   // observe() calls since the last exact report
  };

  SpeculationParams params_;
  MotionPredictor predictor_;
  Camera key_camera_;
  int window_ = 0, subframes_served_ = 0;
  int backoff_ = 0, full_frames_left_ = 0;  // the current backoff, and the full frames it still asks
  bool group_open_ = false;
  bool declined_ = false;  // the cost model closed the window the motion allowed (window_for)
  double key_time_s_ = 0.0;
  double clock_s_ = 0.0;
  Costs cost_;
  // The open group's reported times (its key frame's, once known, plus its served sub-frames').
  double group_ms_ = 0.0;
  int group_subs_ = 0;
  bool group_key_known_ = false;
  double predicted_gain_ = 0.0, measured_gain_ = 0.0;
};

}  // namespace catgs
