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
#pragma once

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
  // when this frame may be served as a sub-frame of the open group.
  bool observe(const Camera& camera, double time_s);

  // Seconds on the renderer's own clock for frames rendered without a time: 1 / F_target a call.
  double advance_clock() { return clock_s_ += 1.0 / params_.target_fps; }

  // Whether a key frame may speculate at all (caching on, W_initial > 0, a motion history, no
  // backoff under way: SpeculationParams::backoff).
  bool window_wanted() const;
  // The predicted camera 1 / F_target after the newest pose, with `key`'s intrinsics (M's pair).
  Camera next_camera(const Camera& key) const { return predicted_camera(key, 1); }
  // W for the largest per-frame screen motion M (pixels): motion_adaptive_window().
  int window_for(float max_motion_px) const { return motion_adaptive_window(max_motion_px, params_); }
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

 private:
  Camera predicted_camera(const Camera& intrinsics, int frames_ahead) const;
  // The key frame now being planned closes an open group that served fewer than min_served
  // sub-frames, with the backoff on: it renders in full, as the first frame of the backoff.
  bool closes_poor_group() const {
    return params_.backoff.frames > 0 && group_open_ && subframes_served_ < params_.backoff.min_served;
  }

  SpeculationParams params_;
  MotionPredictor predictor_;
  Camera key_camera_;
  int window_ = 0, subframes_served_ = 0;
  int backoff_ = 0, full_frames_left_ = 0;  // the current backoff, and the full frames it still asks
  bool group_open_ = false;
  double clock_s_ = 0.0;
};

}  // namespace catgs
