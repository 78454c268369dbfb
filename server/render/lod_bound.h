// The level-of-detail bound each frame of a session draws at (issue 46; the cut itself is
// render_core/forward_model/lod.h, the same on both cores).
//
// Two things set it:
// - The session's size. The bound is given in pixels of a picture whose shorter side is
//   `reference_lines` (720) and scales with the session's shorter side below that: a session
//   streaming 320x180 draws at a quarter of the bound, so the cut is as fine relative to its
//   picture as at 720p (a fixed pixel bound lost far more against a supersampled render at
//   320x180 than at 720p; docs/history/level_of_detail.md "Level of detail in the server"). Above it the
//   bound stays as given (the yardstick chose 2 px at 720p and at 1080p alike).
// - A splat budget: at most that many Gaussians in a frame's cut, predicted from the LOD tree
//   before the frame is drawn (CutCounter: the chunks of the cut whose boxes meet the view
//   frustum, kChunkSize Gaussians each). Over it, the bound steps up a ladder of x sqrt(2) steps
//   (at most 16x the size's bound); the screen-space error of a node falls with its distance, so
//   each step merges far detail first. It steps back down one step a frame only when the finer
//   step's count fits within 3/4 of the budget (hysteresis). The choice depends on the pose and
//   the budget alone, never on timing: a camera standing still keeps its cut.
// The ladder stops at a ceiling, --lod-max-error (issue 72): the coarsest bound the budget may
// raise a frame to, at `reference_lines` and scaled with the size as the bound is (the server's
// default is its default bound, 4 px: the coarsest bound within 1 dB of the earlier 2 px picture
// on the yardstick's three real paths; the next step is not, on one: RESULTS.md "Level of
// detail"). So by default the budget never raises the bound: it only tells the door. A frame
// whose cut at the ceiling still passes the budget draws at the ceiling over budget
// (LodBoundChooser::over_budget); after kShortStreak such frames in a row of one session, the door
// refuses the GPU's next visitor (ServerMetrics::gpu_budget_short) rather than blur or slow every
// visitor's view.
// The budget is --splat-budget N a frame, or, for CUDA sessions by default (auto), sized from the
// GPU's measured throughput: the best Gaussians per millisecond that GPU has shown (a frame's
// Gaussians over its render time, times the frames rendering with it; ServerMetrics::
// gpu_splats_per_ms), times a 60 Hz frame slot, times a share (--splat-budget-share, 0.4: the
// best frame's rate overstates what a loaded GPU sustains; RESULTS.md "Level of detail"), shared by the
// sessions rendering on that GPU, rounded down to a power of sqrt(2) so small changes of the
// estimate do not move the cut. A scene without LOD has no cut to coarsen: the bound is unused.
#pragma once

#include <cstdint>
#include <vector>

#include "camera/camera.h"
#include "scene/gaussian_model.h"

namespace catgs::server {

// Defaults: the server's (server_options.h; ServerDefaults.ASessionWithoutOptionsRunsTheServersDefaults
// holds them equal), so a test or fuzz target that builds settings runs what a server runs.
struct LodSettings {
  float bound_px = 4.0f;           // --lod-error: the bound at reference_lines; 0 = full detail
  int reference_lines = 720;       // the shorter side at which the bound is bound_px
  std::uint64_t splat_budget = 0;  // --splat-budget N: Gaussians a frame's cut (0: none)
  bool auto_budget = true;         // --splat-budget auto (the default): from the GPU's throughput
  // --lod-max-error: the coarsest bound the budget may raise a frame to, px at reference_lines
  // (0: the ladder's top, LodBoundChooser::kSteps above the bound).
  float max_bound_px = 4.0f;
  // --splat-budget-share: the share of the GPU's measured throughput the auto budget hands out.
  double budget_share = 0.4;
  // What the two bounds give, said once: the ladder steps the budget may raise a frame's bound
  // (lod_max_steps), and the coarsest bound that allows, px at reference_lines.
  int max_steps() const;
  float coarsest_bound_px() const;
};

// The ladder steps above `bound_px` that stay within `max_bound_px` (0: LodBoundChooser::kSteps).
int lod_max_steps(float bound_px, float max_bound_px);

// bound_px x min(1, shorter side / reference_lines). 0 stays 0 (full detail).
float size_scaled_lod_bound(float bound_px, int width, int height, int reference_lines);

// The auto budget never asks a frame for fewer Gaussians than this. Below about a million a
// frame's cost is mostly fixed (the picture's tiles, the sort's passes), so a coarser cut saves
// little and costs detail; and without a floor one slow early frame (a cold start on a small
// scene) sized a budget under the 100 k Gaussians a throughput sample needs, and the cut stayed
// at the ladder's top for good (the GPU check on biker; docs/history/level_of_detail.md "Level of
// detail in the server").
inline constexpr std::uint64_t kAutoBudgetFloor = std::uint64_t{1} << 20;

// The auto budget (see above): Gaussians a frame for one of `sessions` sessions sharing a GPU
// that draws `splats_per_ms`, `share` of it handed out, at least kAutoBudgetFloor; 0 (no budget)
// while the throughput is not known yet.
std::uint64_t auto_splat_budget(double splats_per_ms, std::int64_t sessions, double share = 0.4);

// Counts the Gaussians of a LOD cut inside a view without visiting the nodes below the cut: the
// tree from its roots down (children lists built once from LodNode::parent).
class CutCounter {
 public:
  // `model` must outlive the counter; a model without LOD counts nothing (splats() is 0).
  explicit CutCounter(const GaussianModel& model);
  bool has_lod() const { return !roots_.empty(); }
  // Gaussians (kChunkSize per drawn chunk, padding included) of the cut at bound `tau` pixels seen
  // by `camera`, counting only chunks whose node box (of its leaves' means) meets the view frustum
  // widened by 15% on each side.
  std::uint64_t splats(const Camera& camera, float tau) const;
  // The counts at two bounds, `coarse` >= `fine`, in one walk of the tree (the finer cut's).
  struct Counts {
    std::uint64_t coarse = 0, fine = 0;
  };
  Counts splats(const Camera& camera, float coarse, float fine) const;

 private:
  const GaussianModel& model_;
  std::vector<std::uint32_t> roots_;
  std::vector<std::uint32_t> child_begin_;  // node c's children: children_[child_begin_[c] .. [c + 1])
  std::vector<std::uint32_t> children_;
};

// One session's bound, frame by frame (the ladder and hysteresis above).
class LodBoundChooser {
 public:
  static constexpr int kSteps = 8;  // ladder steps above the size's bound: up to x16

  // The bound for a frame of `camera` whose size-scaled bound is `base` px under `budget`
  // Gaussians (0: no budget, `base` itself), at most `max_steps` steps above `base`.
  float choose(const CutCounter& counter, const Camera& camera, float base, std::uint64_t budget,
               int max_steps = kSteps);
  int step() const { return step_; }
  // The cut's predicted Gaussians at the chosen bound (0 when no budget was in force).
  std::uint64_t predicted_splats() const { return predicted_; }
  // The last choice reached the ceiling and its cut still passes the budget; over_budget_streak:
  // how many choices in a row did (one view, or a budget sized from a GPU's first frames, is no
  // lack of room: the door reads a streak, kShortStreak).
  bool over_budget() const { return over_budget_; }
  int over_budget_streak() const { return over_budget_streak_; }
  static constexpr int kShortStreak = 30;  // half a second at 60 frames/s

  static float bound_at(float base, int step);

 private:
  int step_ = 0;
  std::uint64_t predicted_ = 0;
  bool over_budget_ = false;
  int over_budget_streak_ = 0;
};

}  // namespace catgs::server
