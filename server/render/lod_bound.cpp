#include "render/lod_bound.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "forward_model/chunk_bounds.h"
#include "forward_model/lod.h"

namespace catgs::server {

float size_scaled_lod_bound(float bound_px, int width, int height, int reference_lines) {
  if (!(bound_px > 0.0f) || reference_lines <= 0) return 0.0f;
  const int shorter = std::max(1, std::min(width, height));
  return bound_px * std::min(1.0f, static_cast<float>(shorter) / static_cast<float>(reference_lines));
}

std::uint64_t auto_splat_budget(double splats_per_ms, std::int64_t sessions, double share) {
  if (!(splats_per_ms > 0.0)) return 0;
  constexpr double kSlotMs = 1000.0 / 60.0;
  const double budget = splats_per_ms * kSlotMs * share / static_cast<double>(std::max<std::int64_t>(1, sessions));
  // Down to a power of sqrt(2): the estimate creeps up as faster frames are seen, the cut should not.
  const double steps = std::floor(std::log2(std::max(budget, 1.0)) * 2.0);
  return std::max(kAutoBudgetFloor, static_cast<std::uint64_t>(std::exp2(steps / 2.0)));
}

CutCounter::CutCounter(const GaussianModel& model) : model_(model) {
  const std::vector<fm::LodNode>& lod = model.lod;
  const std::size_t n = lod.size();
  child_begin_.assign(n + 1, 0);
  for (std::size_t c = 0; c < n; ++c) {
    if (lod[c].parent == fm::kLodNoParent)
      roots_.push_back(static_cast<std::uint32_t>(c));
    else
      child_begin_[lod[c].parent + 1]++;
  }
  for (std::size_t c = 0; c < n; ++c) child_begin_[c + 1] += child_begin_[c];
  children_.resize(child_begin_[n]);
  std::vector<std::uint32_t> fill(child_begin_.begin(), child_begin_.end() - 1);
  for (std::size_t c = 0; c < n; ++c)
    if (lod[c].parent != fm::kLodNoParent) children_[fill[lod[c].parent]++] = static_cast<std::uint32_t>(c);
}

namespace {

enum class Side { outside, straddles, inside };

// Where the box lies against the view frustum widened by `margin` of the picture on each side:
// outside when its eight corners are all beyond one plane (the side planes pass through the
// camera centre, so this holds for corners behind the camera too), inside when all are within
// every plane (then so is all below it: a parent's box holds its children's).
Side box_side(const fm::LodNode& n, const Camera& cam, float margin) {
  const float w = static_cast<float>(cam.width), h = static_cast<float>(cam.height);
  const float left = cam.cx + margin * w, right = cam.cx - (1.0f + margin) * w;
  const float top = cam.cy + margin * h, bottom = cam.cy - (1.0f + margin) * h;
  int out[5] = {0, 0, 0, 0, 0};
  for (int k = 0; k < 8; ++k) {
    const glm::vec3 corner((k & 1) ? n.hi[0] : n.lo[0], (k & 2) ? n.hi[1] : n.lo[1], (k & 4) ? n.hi[2] : n.lo[2]);
    const glm::vec3 p = cam.R * corner + cam.t;
    out[0] += p.z < cam.near_plane;
    out[1] += cam.fx * p.x + left * p.z < 0.0f;
    out[2] += cam.fx * p.x + right * p.z > 0.0f;
    out[3] += cam.fy * p.y + top * p.z < 0.0f;
    out[4] += cam.fy * p.y + bottom * p.z > 0.0f;
  }
  bool inside = true;
  for (int plane : out) {
    if (plane == 8) return Side::outside;
    inside = inside && plane == 0;
  }
  return inside ? Side::inside : Side::straddles;
}

}  // namespace

std::uint64_t CutCounter::splats(const Camera& camera, float tau) const {
  const std::vector<fm::LodNode>& lod = model_.lod;
  if (lod.empty()) return 0;
  const glm::vec3 eye = camera.position();
  const float focal = std::max(camera.fx, camera.fy);
  std::uint64_t chunks = 0;
  // (node, known inside the frustum): below a node inside, no box is tested again.
  std::vector<std::pair<std::uint32_t, bool>> stack;
  for (std::uint32_t r : roots_) stack.emplace_back(r, false);
  while (!stack.empty()) {
    const auto [c, known_inside] = stack.back();
    stack.pop_back();
    const fm::LodNode& n = lod[c];
    const Side side = known_inside ? Side::inside : box_side(n, camera, 0.15f);
    if (side == Side::outside) continue;
    // Drawn: a leaf, or the highest node on its path within the bound (lod.h); else its children.
    if (n.error == 0.0f || (tau > 0.0f && fm::lod_error_px(n, eye, focal) <= tau)) {
      ++chunks;
      continue;
    }
    for (std::uint32_t k = child_begin_[c]; k < child_begin_[c + 1]; ++k)
      stack.emplace_back(children_[k], side == Side::inside);
  }
  return chunks * fm::kChunkSize;
}

int lod_max_steps(float bound_px, float max_bound_px) {
  if (!(max_bound_px > 0.0f) || !(bound_px > 0.0f)) return LodBoundChooser::kSteps;
  // Steps of x sqrt(2); a ceiling a hair under a step (2.828 for 2 x sqrt(2)) still reaches it.
  const float steps = 2.0f * std::log2(max_bound_px / bound_px) + 1e-3f;
  return std::clamp(static_cast<int>(std::floor(steps)), 0, LodBoundChooser::kSteps);
}

float LodBoundChooser::bound_at(float base, int step) { return base * std::exp2(0.5f * static_cast<float>(step)); }

float LodBoundChooser::choose(const CutCounter& counter, const Camera& camera, float base, std::uint64_t budget,
                              int max_steps) {
  over_budget_ = false;
  if (budget == 0 || !(base > 0.0f) || !counter.has_lod()) {
    over_budget_streak_ = 0;
    step_ = 0;
    predicted_ = 0;
    return base;
  }
  max_steps = std::clamp(max_steps, 0, kSteps);
  step_ = std::min(step_, max_steps);
  predicted_ = counter.splats(camera, bound_at(base, step_));
  while (predicted_ > budget && step_ < max_steps) predicted_ = counter.splats(camera, bound_at(base, ++step_));
  over_budget_ = predicted_ > budget;
  over_budget_streak_ = over_budget_ ? over_budget_streak_ + 1 : 0;
  if (predicted_ <= budget && step_ > 0) {
    const std::uint64_t finer = counter.splats(camera, bound_at(base, step_ - 1));
    if (finer * 4 <= budget * 3) {
      --step_;
      predicted_ = finer;
    }
  }
  return bound_at(base, step_);
}

}  // namespace catgs::server
