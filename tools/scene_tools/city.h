// City-scale scenes and the traces that go with them (docs/DESIGN.md "Measuring": large scenes are
// built from real ones by tiling copies on a grid with per-copy yaw, then flown over at low
// altitude), and real camera paths moved onto a scene. Tools only (catgs-scene, catgs-bench,
// catgs-loadgen), with or without CUDA.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "camera/trace.h"
#include "scene/gaussian_model.h"

namespace catgs {

// Scales a scene about the origin by `s` > 0: means * s, log-scales + ln s (SH and opacity are
// scale-free). Throws std::invalid_argument for s <= 0 or non-finite.
void scale_scene(GaussianModel& model, float s);

// The city recipe of docs/DESIGN.md "Measuring": copies of a scene on the cells (i, j) of a
// square grid with i^2 + j^2 <= radius_sq (13 cells for 4: a diamond), `spacing` times the copy's
// horizontal extent apart, each turned about the up axis by a yaw drawn from `seed`
// (deterministic), the whole scaled by `scale`.
struct CityParams {
  int radius_sq = 4;
  float spacing = 1.2f;      // x the horizontal extent of one (scaled) copy
  float scale = 10.0f;       // applied to the base scene first
  uint64_t seed = 20261121;  // yaws
  bool rotate_sh = true;     // rotate view-dependent colour with the yaw
  glm::vec3 up{0.0f};        // zero: estimate_up(base)
};

// What tile_scene built: where the copies are, for trace generators.
struct CityLayout {
  glm::vec3 up{0.0f, -1.0f, 0.0f};       // unit world up
  glm::vec3 centre{0.0f};                // centre of the middle copy's robust bounds (after scale)
  float extent = 0.0f;                   // horizontal extent of one copy (robust, after scale)
  float height = 0.0f;                   // vertical extent of one copy (robust, after scale)
  float spacing = 0.0f;                  // distance between neighbouring cells, world units
  glm::vec3 axis_a{0.0f}, axis_b{0.0f};  // horizontal grid axes (unit)
  std::vector<glm::ivec2> cells;         // (i, j) of each copy
  std::vector<float> yaw_deg;            // per copy
  std::size_t gaussians_per_copy = 0;
};

// Builds the city (copies in cell order, Gaussians of a copy contiguous). Throws
// std::invalid_argument for bad parameters, std::length_error past 2^32 - 1 Gaussians.
GaussianModel tile_scene(const GaussianModel& base, const CityParams& params, CityLayout* layout = nullptr);

// Fly-over of a city (a UAV): a straight line across the grid along axis_a, `altitude` extents
// above the centre, looking forward and pitched down `pitch_deg`, starting `start_cells` before
// the middle copy and ending `end_cells` after it.
struct FlyoverParams {
  float altitude = 0.75f;  // x extent, above the centre
  float pitch_deg = 24.0f;
  float start_cells = -1.5f, end_cells = 1.5f;  // along axis_a, in cells
  float lateral_cells = 0.0f;                   // offset along axis_b, in cells
};
Trace make_city_flyover(const CityLayout& layout, const FlyoverParams& flyover, const GeneratorParams& params);

// A real camera path (INRIA cameras.json key views) moved onto a scene: positions are mapped by
// a similarity (rotation taking the path's mean camera up onto `up`, scale and translation taking
// the point the path looks at onto the scene's robust centre, with the path's mean distance to
// that point becoming `distance_extents` x the scene's robust extent); orientations rotate with
// it. Then interpolated (interpolate_views) at `rate_hz` with `seconds_per_view` per key view and
// resized to width x height (vertical field of view kept). Throws std::invalid_argument for fewer
// than 2 views.
Trace fit_trace_to_scene(const std::vector<Camera>& keys, const GaussianModel& scene, glm::vec3 up,
                         float distance_extents, double rate_hz, double seconds_per_view, int width, int height);

}  // namespace catgs
