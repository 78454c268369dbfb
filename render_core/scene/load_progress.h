// Load progress of a scene file (scene_loader load_scene, the readers): called with (Gaussians
// read, Gaussians in the file) on the loading thread, rising, the last call (total, total).
#pragma once

#include <cstdint>
#include <functional>

namespace catgs {

using LoadProgress = std::function<void(uint64_t done, uint64_t total)>;

// Reports every `step` items of a per-Gaussian loop (call at(i) before item i) and once at the
// end (done()), so a reader's loop pays a compare per Gaussian and a call per step.
class ProgressSteps {
 public:
  ProgressSteps(const LoadProgress& progress, uint64_t total, uint64_t step = 65536)
      : progress_(progress), total_(total), step_(step) {}
  void at(uint64_t i) const {
    if (progress_ && i > 0 && i % step_ == 0) progress_(i, total_);
  }
  void done() const {
    if (progress_) progress_(total_, total_);
  }

 private:
  const LoadProgress& progress_;
  uint64_t total_, step_;
};

}  // namespace catgs
