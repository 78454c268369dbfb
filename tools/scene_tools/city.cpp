#include "scene_tools/city.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>

#include <glm/gtc/quaternion.hpp>

#include "scene/scene_bounds.h"
#include "scene/sh_rotation.h"
#include "base/parallel_for.h"

namespace catgs {

namespace {

glm::vec3 any_perpendicular(glm::vec3 u) {
  return glm::normalize(glm::cross(u, std::fabs(u.x) < 0.9f ? glm::vec3(1, 0, 0) : glm::vec3(0, 0, 1)));
}

// Rotation (quaternion) taking unit vector a onto unit vector b by the shortest arc.
glm::quat arc(glm::vec3 a, glm::vec3 b) {
  const float c = glm::dot(a, b);
  if (c < -0.999999f) return glm::angleAxis(glm::pi<float>(), any_perpendicular(a));
  const glm::vec3 axis = glm::cross(a, b);
  return glm::normalize(glm::quat(1.0f + c, axis.x, axis.y, axis.z));
}

}  // namespace

void scale_scene(GaussianModel& model, float s) {
  if (!(s > 0.0f) || !std::isfinite(s)) throw std::invalid_argument("scale_scene: scale must be positive and finite");
  const float log_s = std::log(s);
  model.codes.reset();  // compact codes (scene/compact_file.h) no longer match
  for (float& v : model.means) v *= s;
  for (float& v : model.log_scales) v += log_s;
}

GaussianModel tile_scene(const GaussianModel& base_in, const CityParams& p, CityLayout* layout_out) {
  if (base_in.size() == 0) throw std::invalid_argument("tile_scene: empty base scene");
  if (p.radius_sq < 0 || !(p.spacing > 0.0f))
    throw std::invalid_argument("tile_scene: radius_sq must be >= 0 and spacing > 0");
  GaussianModel base = base_in;
  scale_scene(base, p.scale);

  CityLayout L;
  L.up = glm::length(p.up) > 0.0f ? glm::normalize(p.up) : estimate_up(base);
  L.axis_a = any_perpendicular(L.up);
  L.axis_b = glm::cross(L.up, L.axis_a);
  const auto [a0, a1] = axis_quantiles(base, L.axis_a, 0.02f);
  const auto [b0, b1] = axis_quantiles(base, L.axis_b, 0.02f);
  const auto [u0, u1] = axis_quantiles(base, L.up, 0.02f);
  L.extent = std::max(a1 - a0, b1 - b0);
  L.height = u1 - u0;
  L.centre = 0.5f * (a0 + a1) * L.axis_a + 0.5f * (b0 + b1) * L.axis_b + 0.5f * (u0 + u1) * L.up;
  L.spacing = p.spacing * L.extent;
  L.gaussians_per_copy = base.size();

  int r = 0;
  while ((r + 1) * (r + 1) <= p.radius_sq) ++r;
  std::mt19937_64 rng(p.seed);
  for (int i = -r; i <= r; ++i)
    for (int j = -r; j <= r; ++j)
      if (i * i + j * j <= p.radius_sq) {
        L.cells.push_back({i, j});
        // Raw 53-bit draw, not std::uniform_real_distribution: identical on every standard library.
        L.yaw_deg.push_back(static_cast<float>(static_cast<double>(rng() >> 11) * 0x1.0p-53 * 360.0));
      }
  const std::size_t n = base.size(), copies = L.cells.size();
  if (n * copies > std::numeric_limits<uint32_t>::max())
    throw std::length_error("tile_scene: " + std::to_string(n * copies) + " Gaussians exceed 2^32 - 1");

  GaussianModel city;
  city.name = base_in.name + "_city" + std::to_string(copies);
  city.sh_degree = base.sh_degree;
  city.resize(n * copies);
  const std::size_t K3 = static_cast<std::size_t>(base.sh_coeffs()) * 3;
  constexpr std::size_t kChunk = 16384;
  const std::size_t chunks_per_copy = (n + kChunk - 1) / kChunk;
  std::vector<glm::mat3> R(copies);
  std::vector<glm::quat> Q(copies);
  std::vector<ShRotation> S(copies);
  for (std::size_t c = 0; c < copies; ++c) {
    Q[c] = glm::angleAxis(glm::radians(L.yaw_deg[c]), L.up);
    R[c] = glm::mat3_cast(Q[c]);
    S[c] = make_sh_rotation(p.rotate_sh ? base.sh_degree : 0, R[c]);
  }
  parallel_for(copies * chunks_per_copy, 1, [&](std::size_t task) {
    const std::size_t c = task / chunks_per_copy;
    const std::size_t begin = (task % chunks_per_copy) * kChunk, end = std::min(n, begin + kChunk);
    const glm::vec3 offset =
        L.spacing * (static_cast<float>(L.cells[c].x) * L.axis_a + static_cast<float>(L.cells[c].y) * L.axis_b);
    for (std::size_t i = begin; i < end; ++i) {
      const std::size_t o = c * n + i;
      const glm::vec3 m(base.means[3 * i], base.means[3 * i + 1], base.means[3 * i + 2]);
      const glm::vec3 m2 = R[c] * (m - L.centre) + L.centre + offset;
      for (int a = 0; a < 3; ++a) {
        city.means[3 * o + a] = m2[a];
        city.log_scales[3 * o + a] = base.log_scales[3 * i + a];
      }
      const glm::quat q(base.rotations[4 * i], base.rotations[4 * i + 1], base.rotations[4 * i + 2],
                        base.rotations[4 * i + 3]);  // (w, x, y, z)
      const glm::quat q2 = Q[c] * q;                 // the Gaussian's frame turns with the copy
      city.rotations[4 * o] = q2.w;
      city.rotations[4 * o + 1] = q2.x;
      city.rotations[4 * o + 2] = q2.y;
      city.rotations[4 * o + 3] = q2.z;
      city.opacity_logits[o] = base.opacity_logits[i];
      std::copy_n(&base.sh[i * K3], K3, &city.sh[o * K3]);
      S[c].apply(&city.sh[o * K3]);
    }
  });
  if (layout_out) *layout_out = std::move(L);
  return city;
}

Trace make_city_flyover(const CityLayout& L, const FlyoverParams& f, const GeneratorParams& params) {
  GeneratorParams g = params;
  g.up = L.up;
  const glm::vec3 lift = f.altitude * L.extent * L.up;
  const glm::vec3 side = f.lateral_cells * L.spacing * L.axis_b;
  const glm::vec3 start = L.centre + lift + side + f.start_cells * L.spacing * L.axis_a;
  const glm::vec3 end = L.centre + lift + side + f.end_cells * L.spacing * L.axis_a;
  return make_flyover(start, end, f.pitch_deg, g);
}

Trace fit_trace_to_scene(const std::vector<Camera>& keys, const GaussianModel& scene, glm::vec3 up,
                         float distance_extents, double rate_hz, double seconds_per_view, int width, int height) {
  if (keys.size() < 2) throw std::invalid_argument("fit_trace_to_scene: needs at least 2 views");
  up = glm::normalize(up);
  // The point the path looks at: least squares closest point to all optical axes.
  glm::dmat3 A(0.0);
  glm::dvec3 b(0.0), up_sum(0.0), centroid(0.0);
  for (const Camera& c : keys) {
    const glm::mat3 c2w = glm::transpose(c.R);
    const glm::dvec3 f = glm::normalize(glm::dvec3(c2w[2]));
    const glm::dvec3 pos(c.position());
    const glm::dmat3 P = glm::dmat3(1.0) - glm::outerProduct(f, f);
    A += P;
    b += P * pos;
    up_sum -= glm::dvec3(c2w[1]);  // camera y is down
    centroid += pos;
  }
  centroid /= static_cast<double>(keys.size());
  glm::dvec3 look = centroid;
  if (std::fabs(glm::determinant(A)) > 1e-9) look = glm::inverse(A) * b;
  double mean_dist = 0.0;
  for (const Camera& c : keys) mean_dist += glm::length(glm::dvec3(c.position()) - look);
  mean_dist /= static_cast<double>(keys.size());
  if (!(mean_dist > 1e-9)) mean_dist = 1.0;

  const Bounds rb = robust_bounds(scene);
  const glm::vec3 ext = rb.extent();
  const float extent = std::max(ext.x, std::max(ext.y, ext.z));
  const glm::quat Q = arc(glm::normalize(glm::vec3(up_sum)), up);
  const float s = distance_extents * extent / static_cast<float>(mean_dist);
  std::vector<Camera> moved;
  moved.reserve(keys.size());
  for (const Camera& c : keys) {
    const glm::vec3 pos = rb.center() + s * (Q * (c.position() - glm::vec3(look)));
    const glm::quat rot = glm::normalize(Q * c.orientation());
    moved.push_back(Camera::from_pose(pos, rot, c.vertical_fov_deg(), width, height));
  }
  return interpolate_views(moved, rate_hz, seconds_per_view);
}

}  // namespace catgs
