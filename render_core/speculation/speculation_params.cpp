#include "speculation/speculation_params.h"

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
  check(p.target_fps > 0.0, "target fps must be positive");
  check(p.predictor.fit_window_s > 0.0 && p.predictor.fit_window_s <= 1.0,
        "motion predictor window must be in (0, 1] s");
  check(p.predictor.acceleration_window_s >= 0.0 && p.predictor.acceleration_window_s <= 1.0,
        "motion predictor acceleration window must be in [0, 1] s");
}

}  // namespace catgs
