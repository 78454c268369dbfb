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

// The view frustum widened by `margin` of the picture on each side, as five planes over world
// points x: a_j . x + b_j >= 0 on the inner side of plane j (the near plane, then left, right, top,
// bottom; the side planes pass through the camera centre). Set once a count.
struct FrustumPlanes {
  glm::vec3 a[5], a_abs[5];
  float b[5];
  FrustumPlanes(const Camera& cam, float margin) {
    const float w = static_cast<float>(cam.width), h = static_cast<float>(cam.height);
    const float left = cam.cx + margin * w, right = cam.cx - (1.0f + margin) * w;
    const float top = cam.cy + margin * h, bottom = cam.cy - (1.0f + margin) * h;
    // In camera space p = R x + t: z - near >= 0, fx p.x + left p.z >= 0, -(fx p.x + right p.z) >= 0,
    // fy p.y + top p.z >= 0, -(fy p.y + bottom p.z) >= 0.
    const glm::vec3 n[5] = {{0.0f, 0.0f, 1.0f},
                            {cam.fx, 0.0f, left},
                            {-cam.fx, 0.0f, -right},
                            {0.0f, cam.fy, top},
                            {0.0f, -cam.fy, -bottom}};
    const glm::mat3 rt = glm::transpose(cam.R);
    for (int j = 0; j < 5; ++j) {
      a[j] = rt * n[j];  // n . (R x + t) = (R^T n) . x + n . t
      a_abs[j] = glm::abs(a[j]);
      b[j] = glm::dot(n[j], cam.t) - (j == 0 ? cam.near_plane : 0.0f);
    }
  }
};

// Where the node's box lies against the planes: outside when it lies wholly beyond one plane (for
// the side planes that holds for boxes behind the camera too), inside when wholly within every
// one (then so is all below it: a parent's box holds its children's). A plane's value over the
// box spans its value at the centre +- the half extents along |a|: the eight corners in one sum
// (this runs for every node a count visits, each frame of each session).
Side box_side(const fm::LodNode& n, const FrustumPlanes& f) {
  const glm::vec3 lo(n.lo[0], n.lo[1], n.lo[2]), hi(n.hi[0], n.hi[1], n.hi[2]);
  const glm::vec3 centre = 0.5f * (lo + hi), half = 0.5f * (hi - lo);
  bool inside = true;
  for (int j = 0; j < 5; ++j) {
    const float at = glm::dot(f.a[j], centre) + f.b[j], reach = glm::dot(f.a_abs[j], half);
    if (at + reach < 0.0f) return Side::outside;
    inside = inside && at - reach >= 0.0f;
  }
  return inside ? Side::inside : Side::straddles;
}

bool drawn_at(const fm::LodNode& n, float error_px, float tau) {
  return n.error == 0.0f || (tau > 0.0f && error_px <= tau);
}

}  // namespace

std::uint64_t CutCounter::splats(const Camera& camera, float tau) const { return splats(camera, tau, tau).coarse; }

CutCounter::Counts CutCounter::splats(const Camera& camera, float coarse, float fine) const {
  const std::vector<fm::LodNode>& lod = model_.lod;
  if (lod.empty()) return {};
  const glm::vec3 eye = camera.position();
  const float focal = std::max(camera.fx, camera.fy);
  const FrustumPlanes planes(camera, 0.15f);
  std::uint64_t coarse_chunks = 0, fine_chunks = 0;
  // One walk down to the finer cut serves both (the coarser cut lies on or above it). A visit:
  // the node, whether its box is known inside the frustum (then no box below it is tested), and
  // whether the coarser cut was drawn above it.
  struct Visit {
    std::uint32_t node;
    bool known_inside, coarse_above;
  };
  std::vector<Visit> stack;
  for (std::uint32_t r : roots_) stack.push_back({r, false, false});
  while (!stack.empty()) {
    const Visit v = stack.back();
    stack.pop_back();
    const fm::LodNode& n = lod[v.node];
    const Side side = v.known_inside ? Side::inside : box_side(n, planes);
    if (side == Side::outside) continue;
    // Drawn: a leaf, or the highest node on its path within the bound (lod.h); else its children.
    const float error_px = n.error == 0.0f ? 0.0f : fm::lod_error_px(n, eye, focal);
    const bool coarse_here = !v.coarse_above && drawn_at(n, error_px, coarse);
    coarse_chunks += coarse_here ? 1 : 0;
    if (drawn_at(n, error_px, fine)) {
      ++fine_chunks;
      continue;
    }
    for (std::uint32_t k = child_begin_[v.node]; k < child_begin_[v.node + 1]; ++k)
      stack.push_back({children_[k], side == Side::inside, v.coarse_above || coarse_here});
  }
  return {coarse_chunks * fm::kChunkSize, fine_chunks * fm::kChunkSize};
}

int lod_max_steps(float bound_px, float max_bound_px) {
  if (!(max_bound_px > 0.0f) || !(bound_px > 0.0f)) return LodBoundChooser::kSteps;
  // Steps of x sqrt(2); a ceiling a hair under a step (2.828 for 2 x sqrt(2)) still reaches it.
  const float steps = 2.0f * std::log2(max_bound_px / bound_px) + 1e-3f;
  return std::clamp(static_cast<int>(std::floor(steps)), 0, LodBoundChooser::kSteps);
}

int LodSettings::max_steps() const { return lod_max_steps(bound_px, max_bound_px); }

float LodSettings::coarsest_bound_px() const { return LodBoundChooser::bound_at(bound_px, max_steps()); }

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
  // This step's count and, above the size's bound, the finer step's (to step down) in one walk.
  const int from = step_;
  std::uint64_t finer = 0;
  if (step_ > 0) {
    const CutCounter::Counts both = counter.splats(camera, bound_at(base, step_), bound_at(base, step_ - 1));
    predicted_ = both.coarse;
    finer = both.fine;
  } else {
    predicted_ = counter.splats(camera, base);
  }
  while (predicted_ > budget && step_ < max_steps) predicted_ = counter.splats(camera, bound_at(base, ++step_));
  over_budget_ = predicted_ > budget;
  over_budget_streak_ = over_budget_ ? over_budget_streak_ + 1 : 0;
  // Down one step where the finer step fits with a quarter to spare (a step just climbed came
  // from a finer one over the budget).
  if (predicted_ <= budget && step_ > 0 && step_ == from && finer * 4 <= budget * 3) {
    --step_;
    predicted_ = finer;
  }
  return bound_at(base, step_);
}

}  // namespace catgs::server
