// Speculation planning for the catgs pipeline (paper sec. 3.1 "Motion Adaptive Adjustment",
// sec. 3.2, sec. 3.4; DESIGN.md 1-3).
#pragma once

#include <cstddef>

namespace catgs {

struct SpeculationParams {
  int initial_window = 4;         // W_initial: sub-frames after a key frame
  // The shortest window worth a speculative key frame (SpeculationPlanner::window_for): a key
  // frame whose motion-adaptive W falls below it renders in full instead (W = 0, the exact
  // pipeline's stages), because a group that short does not repay its key frame's longer list
  // and path-wide pre-processing. 0 or 1: the paper's rule alone.
  int min_window = 1;
  // Speculation backoff (SpeculationPlanner::start_group): a group that closes having served
  // fewer than `min_served` sub-frames did not repay its key frame (city bicycle, H100: a
  // speculative key frame 4.67 ms, a full frame 2.69, a sub-frame 1.81, so a group needs about 2
  // sub-frames to break even), and the next `backoff_frames` frames render in full (W = 0) before speculating
  // again; each poor group in a row doubles that, up to 8x; a group that repays resets it.
  // 0 frames: no backoff. Measured side by side on the H100 (1080p, catgs FPS / exact FPS, backoff
  // 0 / 2 / 4 / 8 / 16 frames): city bicycle 0.94 / 0.99 / 0.99 / 1.00 / 1.00, city flowers
  // 0.94 / 0.98 / 0.97 / 0.98 / 0.96, city tandt_train 1.75 / 1.75 / 1.75 / 1.74 / 1.72,
  // tumblewood x10 bicycle 0.92 / 0.93 / 0.93 / 0.94 / 0.90 (tests/gpu/RESULTS.md). Again on
  // 2026-11-22 (0 / 2 frames): city bicycle 1.070 / 1.112, flowers 1.016 / 1.053.
  int backoff_frames = 2;
  int min_served = 2;
  float depth_threshold = 0.4f;   // d: only Gaussians deeper than this (world units) set M
  float tile_size = 16.0f;        // l, pixels
  double target_fps = 120.0;      // F_target: the predicted path is sampled at k / F_target
  float trail_slack = 0.1f;       // trails hold the sampled ellipses scaled by 1 + slack
  float trail_margin_px = 0.0f;   // and widened by this many pixels (prediction error)
  // and by this fraction of the Gaussian's own screen motion over the window (prediction error
  // grows with how far the prediction carries a Gaussian; fm::build_trail). 0.1 cut the key
  // frames on the fitted bicycle and flowers paths by 24-56% (H100, tests/gpu/RESULTS.md), for key
  // lists 1.1-1.6x longer.
  float trail_motion_margin = 0.1f;
  bool frustum_and_sort_cache = true;  // false (--no-cache): every frame is a key frame
  bool task_splitting = true;          // false (--no-split)
  // Task splitting's slice length: the average load l = L / t (paper sec. 3.4) or this many
  // entries, whichever is larger; a tile splits above twice that. A later slice of a tile that
  // starts before an earlier one finishes blends, at the pixels that earlier slice will stop,
  // Gaussians hidden there (rasterize_slices.cu ends a pixel's composition at the slice where it
  // stops, and skips it only in slices that start after), so very short slices cost more than
  // they balance. 0: the paper's rule alone. Measured side by side on the H100 (1080p, catgs FPS /
  // exact FPS, floor 1024 / 2048 / 3072, 2026-11-22): city flowers 1.064 / 1.053 / 1.035,
  // bicycle 1.117 / 1.112 / 1.099, tandt_train 2.635 / 2.612 / 2.530; tumblewood x10 flowers
  // 1.047 / 1.101 / 1.132, bicycle 0.977 / 0.979 / 1.013, tandt_train 1.205 / 1.280 / 1.301
  // (tests/gpu/RESULTS.md). The two scenes want opposite floors; 2048 is the compromise.
  int min_slice_entries = 2048;
  bool early_termination = true;       // stop a pixel when T would drop below 1e-4
  // The motion predictor's fit window (MotionPredictorParams::fit_window_s), seconds: a longer
  // one averages out more input jitter, a shorter one lags less behind a changing velocity.
  double predictor_window_s = 0.05;
  // The motion predictor's acceleration window (MotionPredictorParams::acceleration_window_s),
  // seconds; 0 predicts at constant velocity.
  double predictor_acceleration_window_s = 0.1;
};

// How a key frame widens its trails (fm::build_trail): the parameters' values with a window, none
// without one (W = 0: the path is the key camera alone, and the trail its exact ellipse).
struct TrailWidening {
  float slack = 0.0f, margin_px = 0.0f, motion_margin = 0.0f;
};
inline TrailWidening trail_widening(const SpeculationParams& p, int window) {
  if (window <= 0) return {};
  return {p.trail_slack, p.trail_margin_px, p.trail_motion_margin};
}

// The motion-adaptive window (paper sec. 3.1): M is the largest per-frame screen motion (pixels)
// of the visible Gaussians deeper than d. W = W_initial while M <= l, else floor(W_initial * l / M);
// 0 means no speculation: render every frame in full.
inline int motion_adaptive_window(float max_motion_px, const SpeculationParams& p) {
  if (p.initial_window <= 0) return 0;
  if (max_motion_px != max_motion_px) return 0;  // NaN: no trustworthy motion, no speculation
  if (max_motion_px <= p.tile_size) return p.initial_window;
  return static_cast<int>(static_cast<float>(p.initial_window) * p.tile_size / max_motion_px);
}

// Load-aware task splitting (paper sec. 3.4, supplementary Alg. 1): with L entries over t tiles and
// average l = L / t, a tile holding more than 2l entries is cut into slices of about l entries, the
// first slice taking the remainder. A slice is [begin, end) of the sorted render list.
struct TileSlice {
  unsigned tile;
  unsigned begin, end;
  unsigned index;  // k: 0 for a tile's first slice
};

}  // namespace catgs
