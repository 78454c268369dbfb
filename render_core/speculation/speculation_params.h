// The parameters of the catgs pipeline (paper sec. 3.1 "Motion Adaptive Adjustment", sec. 3.2, sec.
// 3.4; docs/DESIGN.md "Speculation"), grouped by where they come from: the paper's own parameters,
// the switches of its ablation tables, and margins tuned beyond the paper. Each tuned default was
// chosen by a side-by-side measurement recorded under the section named beside it: in
// tests/gpu/RESULTS.md ("Where the tuned defaults come from") or, for how it was chosen,
// docs/history/render_core_speculation.md. Command lines set them by name (speculation/settings.h).
#pragma once

#include <cstddef>

#include "speculation/motion_predictor.h"

namespace catgs {

// The most sub-frames a key frame may serve (W_initial's upper bound). The speculation path is
// the key camera plus W predicted cameras, passed by value to the CUDA kernels.
inline constexpr int kMaxWindow = 32;
inline constexpr int kMaxPathCameras = kMaxWindow + 1;

// How far a key frame widens each Gaussian's trail beyond the ellipses it sampled on the
// predicted path (fm::build_trail), for prediction error.
struct TrailMargins {
  float slack = 0.1f;      // the level scaled by 1 + slack
  float margin_px = 0.0f;  // plus this many pixels
  // plus this fraction of the Gaussian's own screen motion over the window: an error in the
  // camera's velocity moves each Gaussian in proportion to its own motion (RESULTS.md, "Trail
  // margins").
  float motion_margin = 0.05f;
};

// Speculation backoff (SpeculationPlanner::start_group): a group that closes having served fewer
// than `min_served` sub-frames did not repay its speculative key frame, so the next `frames`
// frames render in full (W = 0) before speculating again; each poor group in a row doubles that,
// up to 8x; a group that repays resets it. frames = 0: no backoff. (tests/gpu/RESULTS.md,
// "Speculation backoff", and docs/history/render_core_speculation.md, "Speculation backoff 4
// frames / 4 sub-frames": 4 and 4 were faster than 2 and 2 on five of the six
// real-path rows and equal on the sixth, once frames without a window cost what exact frames do.)
// min_served is given for a group of W_initial sub-frames and scales with the group's window: a
// group of W sub-frames must serve ceil(min_served x W / W_initial) (issue 48: a motion-narrowed
// group of W = 2 could never serve 4, so every one was poor). With the cost model on
// (SpeculationParams::cost_model) a group is poor when it served fewer than its measured
// break-even count instead; windows the model declines double the backoff on to 32x, so a path
// where windows never pay probes one in over a hundred frames.
struct SpeculationBackoff {
  int frames = 4;
  int min_served = 4;
};

struct SpeculationParams {
  // The paper's parameters.
  int initial_window = 4;        // W_initial: sub-frames after a key frame, 0..kMaxWindow
  float depth_threshold = 0.4f;  // d: only Gaussians deeper than this (world units) set M
  float tile_size = 16.0f;       // l, pixels
  // F_target: the predicted path is sampled at k / F_target, and sub-frame k of a group is the
  // pose stamped nearest k / F_target after its key frame. 0 (the default): the pose clock's own
  // rate, measured from the poses' stamps (MotionPredictor::pose_interval_s), so a session sending
  // 60 poses/s speculates over 60 Hz steps (issue 48: a fixed 120 put sub-frames 3 and 4 of a
  // 60 Hz session past the trail's end). A clock slower than 30 Hz counts as 30 Hz
  // (SpeculationPlanner::kLongestPoseInterval_s).
  double target_fps = 0.0;

  // The paper's ablations (Tables 1 and 3).
  bool frustum_and_sort_cache = true;  // false (--no-cache): every frame is a key frame
  bool task_splitting = true;          // false (--no-split): one rasterization task per tile

  // Tuned beyond the paper.
  // A sub-frame keeps the colours its key frame evaluated (view direction from the key camera)
  // instead of evaluating the SH at its own pose: the SH coefficients are the largest read of the
  // sub-frame's features, which are bound by DRAM (issue 36). The colour then lags the view
  // direction by at most a window's camera motion (docs/history/render_core_speculation.md,
  // "Sub-frames keep their key frame's colours, and what else was tried").
  bool subframe_key_colour = true;
  // The cost model (the paper's future work; issue 48): each renderer reports its measured frame
  // times (SpeculationPlanner::record_cost) and a window opens only as wide as the measured
  // costs and the share of sub-frames recent groups served say it repays. Off in the core, where
  // the same poses must give the same decisions on both cores (timings differ); on in the server.
  bool cost_model = false;
  TrailMargins trail;
  SpeculationBackoff backoff;
  // Task splitting's slice length: the paper's average load l = L / t or this many entries,
  // whichever is larger; a tile splits above twice that. A later slice of a tile cannot stop
  // early at pixels an earlier, unfinished slice will saturate, so very short slices cost more
  // than they balance (RESULTS.md, "Slice floors"). 0: the paper's rule alone.
  int min_slice_entries = 2048;
  // The motion predictor's fit windows (docs/history/render_core_speculation.md, "The motion
  // predictor's fit window", "Constant acceleration").
  MotionPredictorParams predictor;

  // A check, not a tuning: false blends every pixel to the end of its list (no stop at T < 1e-4),
  // to show split and unsplit rasterization agree to float rounding.
  bool early_termination = true;
};

// Checks the parameters a planner accepts: a window in 0..kMaxWindow, a backoff in 0..1000
// frames, min_served in 0..kMaxWindow, a non-negative slice floor, a finite F_target >= 0 and
// l, a finite d >= 0, finite trail margins >= 0, a fit window in (0, 1] s and an acceleration
// window in [0, 1] s. Throws std::invalid_argument naming the parameter.
void validate(const SpeculationParams& params);

// How a key frame widens its trails (fm::build_trail): the margins with a window, none without
// one (W = 0: the path is the key camera alone, and the trail its exact ellipse).
struct TrailWidening {
  float slack = 0.0f, margin_px = 0.0f, motion_margin = 0.0f;
};
inline TrailWidening trail_widening(const SpeculationParams& p, int window) {
  if (window <= 0) return {};
  return {p.trail.slack, p.trail.margin_px, p.trail.motion_margin};
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
