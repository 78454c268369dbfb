#include "speculation/speculation_params.h"

#include <cmath>
#include <stdexcept>

namespace catgs {

void validate(const SpeculationParams& p) {
  auto check = [](bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(what);
  };
  check(p.initial_window >= 0 && p.initial_window <= kMaxWindow, "speculation window must be in 0..32");
  check(p.backoff.frames >= 0 && p.backoff.frames <= 1000, "speculation backoff must be in 0..1000 frames");
  check(p.backoff.min_served >= 0 && p.backoff.min_served <= kMaxWindow,
        "sub-frames a group must serve must be in 0..32");
  check(p.min_slice_entries >= 0, "minimum slice length must not be negative");
  check(p.target_fps >= 0.0 && std::isfinite(p.target_fps), "target fps must be >= 0 (0: the pose clock's rate)");
  check(p.tile_size > 0.0f && std::isfinite(p.tile_size), "tile size l must be positive");
  check(p.depth_threshold >= 0.0f && std::isfinite(p.depth_threshold), "depth threshold d must be >= 0");
  check(p.trail.slack >= 0.0f && p.trail.margin_px >= 0.0f && p.trail.motion_margin >= 0.0f &&
            std::isfinite(p.trail.slack) && std::isfinite(p.trail.margin_px) && std::isfinite(p.trail.motion_margin),
        "trail margins must be finite and >= 0");
  check(p.predictor.fit_window_s > 0.0 && p.predictor.fit_window_s <= 1.0,
        "motion predictor window must be in (0, 1] s");
  check(p.predictor.acceleration_window_s >= 0.0 && p.predictor.acceleration_window_s <= 1.0,
        "motion predictor acceleration window must be in [0, 1] s");
}

}  // namespace catgs
