#include "speculation/speculation_planner.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace catgs {

namespace {

bool same_intrinsics(const Camera& a, const Camera& b) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy && a.cx == b.cx && a.cy == b.cy &&
         a.near_plane == b.near_plane && a.far_plane == b.far_plane;
}

}  // namespace

SpeculationPlanner::SpeculationPlanner(const SpeculationParams& params) { set_params(params); }

void SpeculationPlanner::set_params(const SpeculationParams& params) {
  validate(params);
  if (params.predictor.fit_window_s != predictor_.params().fit_window_s ||
      params.predictor.acceleration_window_s != predictor_.params().acceleration_window_s ||
      params.predictor.max_samples != predictor_.params().max_samples ||
      params.predictor.reference_rate_hz != predictor_.params().reference_rate_hz)
    predictor_ = MotionPredictor(params.predictor);  // a new fit: history restarts
  params_ = params;
  group_open_ = declined_ = false;
  backoff_ = full_frames_left_ = 0;  // the measured costs stay: the scene and the GPU are the same
}

double SpeculationPlanner::frame_interval_s() const {
  if (params_.target_fps > 0.0) return 1.0 / params_.target_fps;
  const double measured = predictor_.pose_interval_s();
  return measured > 0.0 ? std::min(measured, kLongestPoseInterval_s) : 1.0 / 120.0;
}

bool SpeculationPlanner::observe(const Camera& camera, double time_s) {
  predictor_.add({time_s, camera.position(), camera.orientation()});
  ++cost_.frames_since_exact;
  const double elapsed = predictor_.latest().time_s - key_time_s_;
  return group_open_ && elapsed >= 0.0 && elapsed <= (window_ + 0.5) * frame_interval_s() &&
         same_intrinsics(camera, key_camera_);
}

bool SpeculationPlanner::window_wanted() const {
  return params_.frustum_and_sort_cache && params_.initial_window > 0 && !predictor_.empty() &&
         full_frames_left_ == 0 && !closes_poor_group();
}

Camera SpeculationPlanner::predicted_camera(const Camera& intrinsics, int frames_ahead) const {
  const TimedPose pose = predictor_.predict(frames_ahead * frame_interval_s());
  Camera c = intrinsics;
  c.R = glm::transpose(glm::mat3_cast(pose.orientation));
  c.t = -(c.R * pose.position);
  return c;
}

std::vector<Camera> SpeculationPlanner::path(const Camera& key, int window) const {
  std::vector<Camera> cameras{key};
  for (int k = 1; k <= window; ++k) cameras.push_back(predicted_camera(key, k));
  return cameras;
}

void SpeculationPlanner::start_group(const Camera& key, int window) {
  // The gain the model expects of the window it chose (window_for saw the share before this close).
  const double expected = params_.cost_model && window > 0 ? expected_frame_ms(window) : -1.0;
  predicted_gain_ = expected > 0.0 && cost_.exact_ms > 0.0 ? cost_.exact_ms / expected : 0.0;
  if (group_open_) {  // the group closes: its served share feeds the cost model
    const double share = static_cast<double>(std::min(subframes_served_, window_)) / window_;
    // Half the last group's: a probe that finds a path slowed down reopens the window at once.
    cost_.served_share = 0.5 * cost_.served_share + 0.5 * share;
    if (group_key_known_ && cost_.exact_ms > 0.0) measured_gain_ = (1 + group_subs_) * cost_.exact_ms / group_ms_;
  }
  group_ms_ = 0.0;
  group_subs_ = 0;
  group_key_known_ = false;
  const bool poor = closes_poor_group() || (declined_ && params_.backoff.frames > 0);
  if (poor) {  // this frame is the first of the backoff's full frames
    // A poor group is a local miss (the path turned): 8x at most. A window the cost model
    // declined is a path where windows do not pay: up to 32x, then a probe (window_for).
    const int most = declined_ ? most_backoff() : 8 * params_.backoff.frames;
    backoff_ = backoff_ == 0 ? params_.backoff.frames : std::min(2 * backoff_, std::max(most, backoff_));
    full_frames_left_ = backoff_ - 1;
  } else if (group_open_) {  // the group repaid its key frame
    backoff_ = 0;
  } else if (full_frames_left_ > 0) {
    --full_frames_left_;
  }
  key_camera_ = key;
  key_time_s_ = predictor_.latest().time_s;
  window_ = window;
  subframes_served_ = 0;
  group_open_ = window > 0;
  declined_ = false;
}

int SpeculationPlanner::window_for(float max_motion_px) {
  const int motion = motion_adaptive_window(max_motion_px, params_);
  declined_ = false;
  if (!params_.cost_model || motion == 0) return motion;
  if (cost_.exact_ms <= 0.0 || cost_.frames_since_exact > kExactRefresh) return 0;  // measure the yardstick
  int best = 0;
  double best_ms = cost_.exact_ms;
  for (int w = 1; w <= motion; ++w) {
    const double ms = expected_frame_ms(w);
    if (ms < 0.0) return motion;  // a cost is not measured yet: open the window to measure it
    if (ms < best_ms) {
      best = w;
      best_ms = ms;
    }
  }
  // Declined windows back off to 32x; at that cap the motion's window opens anyway, as a probe
  // that measures the served share and the costs again (the path may have slowed down).
  if (best == 0 && backoff_ >= most_backoff()) return motion;
  declined_ = best == 0;
  return best;
}

void SpeculationPlanner::record_cost(FrameKind kind, int window, double ms) {
  if (!params_.cost_model || !(ms > 0.0) || !std::isfinite(ms)) return;
  if (cost_.reports[static_cast<std::size_t>(kind)]++ == 0) return;  // the cold first frame
  if (group_open_ && kind == FrameKind::key) {  // the open group's own key frame (reported after it opened)
    group_ms_ = ms;
    group_key_known_ = true;
  } else if (group_open_ && kind == FrameKind::sub && group_key_known_) {
    group_ms_ += ms;
    ++group_subs_;
  }
  if (kind == FrameKind::exact) cost_.frames_since_exact = 0;
  auto average = [ms](double& into) { into = into > 0.0 ? 0.875 * into + 0.125 * ms : ms; };
  switch (kind) {
    case FrameKind::exact:
      average(cost_.exact_ms);
      break;
    case FrameKind::sub:
      average(cost_.sub_ms);
      break;
    case FrameKind::key:
      if (window >= 1 && window <= kMaxWindow) average(cost_.key_ms[static_cast<std::size_t>(window)]);
      break;
  }
}

double SpeculationPlanner::key_ms(int window) const {
  if (cost_.key_ms[static_cast<std::size_t>(window)] > 0.0) return cost_.key_ms[static_cast<std::size_t>(window)];
  if (cost_.exact_ms <= 0.0) return -1.0;
  // The nearest measured window, its overhead over an exact frame scaled linearly to `window`
  // (a trail's list grows with the path it spans).
  for (int d = 1; d <= kMaxWindow; ++d)
    for (int w : {window - d, window + d})
      if (w >= 1 && w <= kMaxWindow && cost_.key_ms[static_cast<std::size_t>(w)] > 0.0)
        return cost_.exact_ms +
               (cost_.key_ms[static_cast<std::size_t>(w)] - cost_.exact_ms) * static_cast<double>(window) / w;
  return -1.0;
}

double SpeculationPlanner::expected_frame_ms(int window) const {
  if (window <= 0) return cost_.exact_ms > 0.0 ? cost_.exact_ms : -1.0;
  const double key = key_ms(window);
  if (key < 0.0) return -1.0;
  // A sub-frame's cost not measured yet (none served) counts as 0, the optimistic bound: a window
  // opens to measure it while groups are expected to serve, and closes once they serve none.
  const double f = cost_.served_share, n = f * window, sub = std::max(0.0, cost_.sub_ms);
  return (key + n * sub + (1.0 - f) * sub) / (1.0 + n);
}

double SpeculationPlanner::break_even_served(int window) const {
  if (window <= 0) return 0.0;
  if (params_.cost_model && cost_.exact_ms > 0.0 && cost_.sub_ms > 0.0) {
    const double key = key_ms(window);
    if (key > 0.0) {
      const double saved = cost_.exact_ms - cost_.sub_ms;  // a served sub-frame's saving
      if (saved <= 0.0) return window + 1.0;               // no count repays
      return std::max(0.0, (key - cost_.exact_ms + cost_.sub_ms) / saved);
    }
  }
  const int initial = std::max(1, params_.initial_window);
  return std::ceil(static_cast<double>(params_.backoff.min_served) * window / initial);
}

}  // namespace catgs
