#include "speculation/speculation_planner.h"

#include <algorithm>
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
      params.predictor.max_samples != predictor_.params().max_samples)
    predictor_ = MotionPredictor(params.predictor);  // a new fit: history restarts
  params_ = params;
  group_open_ = false;
  backoff_ = full_frames_left_ = 0;
}

bool SpeculationPlanner::observe(const Camera& camera, double time_s) {
  predictor_.add({time_s, camera.position(), camera.orientation()});
  return group_open_ && subframes_served_ < window_ && same_intrinsics(camera, key_camera_);
}

bool SpeculationPlanner::window_wanted() const {
  return params_.frustum_and_sort_cache && params_.initial_window > 0 && !predictor_.empty() &&
         full_frames_left_ == 0 && !closes_poor_group();
}

Camera SpeculationPlanner::predicted_camera(const Camera& intrinsics, int frames_ahead) const {
  const TimedPose pose = predictor_.predict(frames_ahead / params_.target_fps);
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
  if (closes_poor_group()) {  // this frame is the first of the backoff's full frames
    backoff_ = backoff_ == 0 ? params_.backoff.frames : std::min(2 * backoff_, 8 * params_.backoff.frames);
    full_frames_left_ = backoff_ - 1;
  } else if (group_open_) {  // the group repaid its key frame
    backoff_ = 0;
  } else if (full_frames_left_ > 0) {
    --full_frames_left_;
  }
  key_camera_ = key;
  window_ = window;
  subframes_served_ = 0;
  group_open_ = window > 0;
}

}  // namespace catgs
