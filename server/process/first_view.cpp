#include "process/first_view.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <stdexcept>

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include "camera/trace.h"
#include "forward_model/chunk_bounds.h"
#include "forward_model/lod.h"
#include "scene/load_blocks.h"
#include "process/order_statistics.h"

namespace catgs::server {

namespace {

constexpr double kPi = 3.14159265358979323846;
const glm::vec3 kMinusY(0.0f, -1.0f, 0.0f);  // the 3DGS convention's up (COLMAP frames, y down)

// The Gaussians a scene's content is judged by: a model with a level of detail holds its leaves
// first (lod/lod_build.h), and its merged levels would count the content again.
// (Leaves first, error 0, then every merged node of error > 0: a binary search.)
std::size_t content_count(const GaussianModel& m) {
  if (m.lod.empty()) return m.size();
  const auto end =
      std::partition_point(m.lod.begin(), m.lod.end(), [](const fm::LodNode& n) { return n.error == 0.0f; });
  return std::min(m.size(), static_cast<std::size_t>(end - m.lod.begin()) * fm::kChunkSize);
}

// Eigenvalues of a symmetric 3x3 matrix, ascending (O. K. Smith, "Eigenvalues of a symmetric
// 3x3 matrix", Communications of the ACM 4(4), 1961: the trigonometric solution of the
// characteristic cubic).
glm::dvec3 symmetric_eigenvalues(const glm::dmat3& a) {
  const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
  const double q = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
  const double p2 =
      (a[0][0] - q) * (a[0][0] - q) + (a[1][1] - q) * (a[1][1] - q) + (a[2][2] - q) * (a[2][2] - q) + 2.0 * off;
  if (p2 <= 1e-30 * std::max(q * q, 1e-300)) return glm::dvec3(q);  // a multiple of I
  const double p = std::sqrt(p2 / 6.0);
  const glm::dmat3 b = (1.0 / p) * (a - q * glm::dmat3(1.0));
  const double r = std::clamp(glm::determinant(b) / 2.0, -1.0, 1.0);
  const double phi = std::acos(r) / 3.0;
  const double largest = q + 2.0 * p * std::cos(phi);
  const double smallest = q + 2.0 * p * std::cos(phi + 2.0 * kPi / 3.0);
  return {smallest, 3.0 * q - largest - smallest, largest};
}

// A unit eigenvector of symmetric `a` for its eigenvalue `lambda`: the longest cross product of
// two rows of (a - lambda I), which are all perpendicular to it. For a repeated eigenvalue any
// vector of its eigenspace would do; the caller treats that case as ambiguous anyway.
glm::dvec3 eigenvector_for(const glm::dmat3& a, double lambda) {
  const glm::dmat3 m = a - lambda * glm::dmat3(1.0);
  const glm::dvec3 r0(m[0][0], m[1][0], m[2][0]), r1(m[0][1], m[1][1], m[2][1]), r2(m[0][2], m[1][2], m[2][2]);
  glm::dvec3 best = glm::cross(r0, r1);
  for (const glm::dvec3& c : {glm::cross(r0, r2), glm::cross(r1, r2)})
    if (glm::dot(c, c) > glm::dot(best, best)) best = c;
  return glm::dot(best, best) > 0.0 ? glm::normalize(best) : glm::dvec3(0.0, -1.0, 0.0);
}

// The q-quantile of v (the element at rank q (n - 1), rounded down). v must not be empty.
float percentile(std::vector<float> v, double q) {
  const auto k = static_cast<std::ptrdiff_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[static_cast<std::size_t>(k)];
}

glm::vec3 mean_at(const GaussianModel& m, std::size_t i) {
  return {m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]};
}

// The whole-scene passes below run on every core and select with order_statistics.h, which
// give exactly the serial values (issue 37: on the 7 M city they took most of a 17 s load).
constexpr std::size_t kBlock = 1 << 18;
void for_blocks(std::size_t n, const std::function<void(std::size_t, std::size_t)>& fn) {
  run_blocks((n + kBlock - 1) / kBlock, 0, [&](uint64_t b) { fn(b * kBlock, std::min(n, (b + 1) * kBlock)); });
}

// The rank-q element of a whole-scene array, as percentile() picks it.
float scene_percentile(const std::vector<float>& v, double q) {
  return kth_smallest(v, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1)));
}

// Into `d` (resized to N): reused across the mean-shift's iterations, so its pages fault once.
void distances_from(const GaussianModel& m, glm::vec3 c, std::vector<float>& d) {
  d.resize(content_count(m));
  for_blocks(content_count(m), [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) d[i] = glm::distance(mean_at(m, i), c);
  });
}

float opacity(const GaussianModel& m, std::size_t i) { return 1.0f / (1.0f + std::exp(-m.opacity_logits[i])); }

// Camera axes in world (rows of the world-to-camera rotation).
glm::vec3 camera_forward(const Camera& c) { return glm::vec3(c.R[0][2], c.R[1][2], c.R[2][2]); }
glm::vec3 camera_down(const Camera& c) { return glm::vec3(c.R[0][1], c.R[1][1], c.R[2][1]); }

// Camera-to-world rotation whose z axis points along `forward` and whose x axis is
// perpendicular to `up` (a level camera).
glm::quat level_orientation(glm::vec3 forward, glm::vec3 up) {
  const glm::vec3 f = glm::normalize(forward);
  glm::vec3 right = glm::cross(-up, f);  // camera x = y (down) x z (forward)
  if (glm::length(right) < 1e-6f) right = glm::cross(glm::vec3(1.0f, 0.0f, 0.0f), f);
  right = glm::normalize(right);
  const glm::vec3 down = glm::cross(f, right);
  return glm::normalize(glm::quat_cast(glm::mat3(right, down, f)));
}

// Where the cameras look when their axes do not meet in front of them (module header).
glm::vec3 fallback_centre(const std::vector<Camera>& cameras) {
  glm::vec3 mean_pos(0.0f), mean_dir(0.0f);
  for (const Camera& c : cameras) {
    mean_pos += c.position() / static_cast<float>(cameras.size());
    mean_dir += camera_forward(c);
  }
  if (glm::length(mean_dir) < 1e-6f) return mean_pos;  // looking every way: the middle
  std::vector<float> spread;
  for (const Camera& c : cameras) spread.push_back(glm::distance(c.position(), mean_pos));
  const float median_spread = percentile(std::move(spread), 0.5);
  const float reach = median_spread > 0.0f ? median_spread : 1.0f;
  return mean_pos + reach * glm::normalize(mean_dir);
}

bool in_front_of_most(const std::vector<Camera>& cameras, glm::vec3 p) {
  std::size_t in_front = 0;
  for (const Camera& c : cameras) in_front += glm::dot(p - c.position(), camera_forward(c)) > 0.0f ? 1 : 0;
  return 2 * in_front > cameras.size();
}

// The camera whose optical axis points most directly at `centre` (the first of equals).
std::size_t most_central_camera(const std::vector<Camera>& cameras, glm::vec3 centre) {
  std::size_t best = 0;
  float best_cos = -2.0f;
  for (std::size_t k = 0; k < cameras.size(); ++k) {
    const glm::vec3 to_centre = centre - cameras[k].position();
    const float cos_angle =
        glm::length(to_centre) > 0.0f ? glm::dot(glm::normalize(to_centre), camera_forward(cameras[k])) : 1.0f;
    if (cos_angle > best_cos) {
      best_cos = cos_angle;
      best = k;
    }
  }
  return best;
}

// The mean-shift density mode (dense_content's header): the opacity-weighted mean of the nearest
// quarter of the Gaussians, repeated from the median until it stops moving.
glm::vec3 density_mode(const GaussianModel& m) {
  const std::size_t n = content_count(m);
  glm::vec3 c;
  for (int a = 0; a < 3; ++a) {
    std::vector<float> v(n);
    for (std::size_t i = 0; i < n; ++i) v[i] = m.means[3 * i + a];
    c[a] = scene_percentile(v, 0.5);
  }
  std::vector<float> alpha(n);  // opacity(m, i), once
  for_blocks(n, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) alpha[i] = opacity(m, i);
  });
  std::vector<float> d;
  for (int iteration = 0; iteration < 50; ++iteration) {
    distances_from(m, c, d);
    const float kernel = scene_percentile(d, 0.25);
    // Serial on purpose: the sums' order, hence their rounding, is the one the tests know.
    glm::dvec3 sum(0.0);
    double weight = 0.0;
    for (std::size_t i = 0; i < n; ++i)
      if (d[i] <= kernel) {
        sum += static_cast<double>(alpha[i]) * glm::dvec3(mean_at(m, i));
        weight += alpha[i];
      }
    if (!(weight > 0.0)) break;  // all transparent: stay at the median
    const glm::vec3 next(sum / weight);
    const bool settled = glm::distance(next, c) <= 1e-4f * kernel;
    c = next;
    if (settled) break;
  }
  return c;
}

// dense_content's radius: grow by percentiles until the next 5% of the Gaussians lie in a sparse
// shell (they need a ball 1.5 times as large) or the density inside falls below 1/100 the core's.
float content_radius(std::vector<float> d, double* share) {
  parallel_sort(d);
  auto at = [&](double q) {
    return std::max(d[static_cast<std::size_t>(q * static_cast<double>(d.size() - 1))], 1e-6f);
  };
  const double core_density = 0.25 / std::pow(at(0.25), 3.0);
  double q = 0.25;
  while (q < 0.975) {
    if (at(std::min(q + 0.05, 0.98)) > 1.5f * at(q)) break;
    const double next = q + 0.01;
    if (next / std::pow(at(next), 3.0) < 0.01 * core_density) break;
    q = next;
  }
  *share = q;
  return at(q);
}

// Mean and covariance of the means within `radius` (distances `d`) and how many there are.
struct BallMoments {
  glm::dvec3 mean{0.0};
  glm::dmat3 covariance{0.0};
  std::size_t count = 0;
};

BallMoments ball_moments(const GaussianModel& m, const std::vector<float>& d, float radius) {
  BallMoments b;
  const std::size_t n = content_count(m);
  for (std::size_t i = 0; i < n; ++i)
    if (d[i] <= radius) {
      b.mean += glm::dvec3(mean_at(m, i));
      ++b.count;
    }
  if (b.count == 0) return b;
  b.mean /= static_cast<double>(b.count);
  for (std::size_t i = 0; i < n; ++i)
    if (d[i] <= radius) {
      const glm::dvec3 e = glm::dvec3(mean_at(m, i)) - b.mean;
      b.covariance += glm::outerProduct(e, e);
    }
  return b;
}

// dense_content's up: the smallest principal axis of a layer near the y axis, else -y.
glm::vec3 content_up(const BallMoments& ball, bool* from_content) {
  *from_content = false;
  if (ball.count < 10) return kMinusY;
  const glm::dvec3 eig = symmetric_eigenvalues(ball.covariance);
  if (!(eig[0] <= 0.5 * eig[1])) return kMinusY;  // not a layer: no vertical axis stands out
  glm::vec3 axis(eigenvector_for(ball.covariance, eig[0]));
  if (glm::dot(axis, kMinusY) < 0.0f) axis = -axis;
  if (glm::dot(axis, kMinusY) < std::cos(glm::radians(45.0f))) return kMinusY;
  *from_content = true;
  return glm::normalize(axis);
}

// The unit vector from the orbit centre to a content-based first view (first_view_pose's
// header): from -z made perpendicular to up, ~17 degrees above the horizon (the ground in view,
// the subject not seen edge-on).
glm::vec3 content_view_offset(glm::vec3 up) {
  up = glm::normalize(up);
  glm::vec3 back = glm::vec3(0.0f, 0.0f, -1.0f) - glm::dot(glm::vec3(0.0f, 0.0f, -1.0f), up) * up;
  if (glm::length(back) < 1e-3f) back = glm::cross(up, glm::vec3(1.0f, 0.0f, 0.0f));  // up along z
  return glm::normalize(glm::normalize(back) + 0.3f * up);
}

// The content box (frame_from_content): the [kBoxTail, 1 - kBoxTail] quantiles of `points` along
// the first view's level axes (its right, `up`, and the horizontal direction between them), its
// centre in world coordinates, and the points inside it.
struct ContentBox {
  glm::vec3 centre{0.0f};
  std::vector<glm::vec3> inside;
};

ContentBox content_box(const std::vector<glm::vec3>& points, glm::vec3 up) {
  const glm::mat3 view = glm::mat3_cast(level_orientation(-content_view_offset(up), up));
  const glm::vec3 right = view[0], vertical = glm::normalize(up), ahead = glm::normalize(glm::cross(right, vertical));
  const glm::vec3 axes[3] = {right, vertical, ahead};
  glm::vec3 lo, hi;
  for (int a = 0; a < 3; ++a) {
    std::vector<float> v;
    v.reserve(points.size());
    for (const glm::vec3& p : points) v.push_back(glm::dot(p, axes[a]));
    lo[a] = scene_percentile(v, kBoxTail);
    hi[a] = scene_percentile(v, 1.0 - kBoxTail);
  }
  ContentBox box;
  for (int a = 0; a < 3; ++a) box.centre += 0.5f * (lo[a] + hi[a]) * axes[a];
  for (const glm::vec3& p : points) {
    bool in = true;
    for (int a = 0; a < 3; ++a) in = in && glm::dot(p, axes[a]) >= lo[a] && glm::dot(p, axes[a]) <= hi[a];
    if (in) box.inside.push_back(p);
  }
  return box;
}

// How far from orbit_centre, back along the view axis of `orientation`, a camera must stand for
// frame.framed_share of the content points to project inside the picture less frame.margin on
// each side, |x/z| <= fit tan_h, |y/z| <= fit tan_v (fit = 1 - 2 margin). A point at camera-frame
// offset (x, y, z) from the centre needs d >= max(|x| / (fit tan_h), |y| / (fit tan_v)) - z.
// Without content points: the distance at which the content sphere fills the narrower field of
// view.
float framing_distance(const SceneFrame& frame, glm::quat orientation, float tan_h, float tan_v) {
  if (frame.content_points.empty())
    return std::max(frame.content_radius, 1e-3f) / std::sin(std::atan(std::min(tan_h, tan_v)));
  const float fit = 1.0f - 2.0f * static_cast<float>(frame.margin);
  const glm::mat3 axes = glm::mat3_cast(orientation);  // columns: right, down, forward
  std::vector<float> need;
  need.reserve(frame.content_points.size());
  for (const glm::vec3& p : frame.content_points) {
    const glm::vec3 rel = p - frame.orbit_centre;
    const float x = glm::dot(rel, axes[0]), y = glm::dot(rel, axes[1]), z = glm::dot(rel, axes[2]);
    need.push_back(std::max(std::fabs(x) / (fit * tan_h), std::fabs(y) / (fit * tan_v)) - z);
  }
  // Never inside the content: at least a tenth of its radius out.
  return std::max(percentile(std::move(need), frame.framed_share), 0.1f * frame.content_radius);
}

}  // namespace

std::optional<glm::vec3> nearest_point_to_lines(const std::vector<glm::vec3>& origins,
                                                const std::vector<glm::vec3>& directions) {
  if (origins.size() < 2 || origins.size() != directions.size()) return std::nullopt;
  glm::dmat3 a(0.0);
  glm::dvec3 b(0.0);
  for (std::size_t i = 0; i < origins.size(); ++i) {
    if (!(glm::length(directions[i]) > 0.0f)) return std::nullopt;
    const glm::dvec3 dir = glm::normalize(glm::dvec3(directions[i]));
    const glm::dmat3 project = glm::dmat3(1.0) - glm::outerProduct(dir, dir);  // onto the line's normal plane
    a += project;
    b += project * glm::dvec3(origins[i]);
  }
  const glm::dvec3 eig = symmetric_eigenvalues(a);
  const double mean_eig = (eig[0] + eig[1] + eig[2]) / 3.0;
  if (!(eig[0] >= 1e-3 * mean_eig)) return std::nullopt;
  const glm::dvec3 p = glm::inverse(a) * b;
  if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) return std::nullopt;
  return glm::vec3(p);
}

SceneFrame frame_from_cameras(const std::vector<Camera>& cameras, const std::string& file) {
  if (cameras.empty()) throw std::invalid_argument("a scene frame needs at least one camera");
  SceneFrame f;
  glm::vec3 up_sum(0.0f);
  std::vector<glm::vec3> origins, axes;
  for (const Camera& c : cameras) {
    up_sum -= camera_down(c);
    origins.push_back(c.position());
    axes.push_back(camera_forward(c));
  }
  f.up = glm::length(up_sum) > 1e-6f ? glm::normalize(up_sum) : kMinusY;
  const std::optional<glm::vec3> meet = nearest_point_to_lines(origins, axes);
  const bool axes_meet = meet && in_front_of_most(cameras, *meet);
  f.orbit_centre = axes_meet ? *meet : fallback_centre(cameras);
  std::vector<float> reach;
  for (const Camera& c : cameras) reach.push_back(glm::distance(c.position(), f.orbit_centre));
  f.scene_scale = std::max(percentile(std::move(reach), 0.5), 1e-6f);

  const std::size_t best = most_central_camera(cameras, f.orbit_centre);
  CameraPose view;
  view.position = cameras[best].position();
  view.orientation = cameras[best].orientation();
  view.vertical_fov_deg = std::clamp(cameras[best].vertical_fov_deg(), 20.0f, 100.0f);
  f.training_view = view;
  f.content_radius = f.scene_scale * std::tan(glm::radians(view.vertical_fov_deg / 2.0f));
  f.source = "cameras " + file + ", camera " + std::to_string(best) + " (file order, from 0) of " +
             std::to_string(cameras.size()) +
             (axes_meet ? ", orbit centre where the optical axes meet"
                        : ", orbit centre ahead of the cameras (their axes do not meet in front of them)");
  return f;
}

DenseContent dense_content(const GaussianModel& model) {
  if (model.size() == 0) throw std::logic_error("dense content of an empty Gaussian model");
  DenseContent c;
  c.mode = density_mode(model);
  std::vector<float> d;
  distances_from(model, c.mode, d);
  c.radius = content_radius(d, &c.share);
  const BallMoments ball = ball_moments(model, d, c.radius);
  c.centre = ball.count > 0 ? glm::vec3(ball.mean) : c.mode;
  c.up = content_up(ball_moments(model, d, 1.5f * c.radius), &c.up_from_content);
  return c;
}

// Every `stride`-th point, at most kMaxFramedPoints of them.
std::vector<glm::vec3> evenly_picked(const std::vector<glm::vec3>& points) {
  std::vector<glm::vec3> picked;
  const std::size_t stride = points.size() / kMaxFramedPoints + 1;
  for (std::size_t i = 0; i < points.size(); i += stride) picked.push_back(points[i]);
  return picked;
}

// Every `stride`-th content Gaussian's mean and opacity (the only values the first view reads), as
// a model without LOD: the sample frame_from_content judges a large model by.
GaussianModel content_sample(const GaussianModel& m, std::size_t stride) {
  const std::size_t n = (content_count(m) + stride - 1) / stride;
  GaussianModel s;
  s.means.resize(3 * n);
  s.opacity_logits.resize(n);
  for_blocks(n, [&](std::size_t begin, std::size_t end) {
    for (std::size_t j = begin; j < end; ++j) {
      for (int a = 0; a < 3; ++a) s.means[3 * j + a] = m.means[3 * (j * stride) + a];
      s.opacity_logits[j] = m.opacity_logits[j * stride];
    }
  });
  return s;
}

SceneFrame frame_from_content(const GaussianModel& whole, std::size_t judged) {
  const std::size_t stride = (content_count(whole) + judged - 1) / std::max<std::size_t>(judged, 1);
  GaussianModel sample;
  if (stride > 1) sample = content_sample(whole, stride);
  const GaussianModel& model = stride > 1 ? sample : whole;
  const DenseContent c = dense_content(model);
  SceneFrame f;
  f.up = c.up;
  f.content_radius = c.radius;
  // The ball holds the dense core; an object's box is taken from a ball 1.5 times as large (as
  // content_up's), since the core's radius stops at the 98th percentile of distances from the
  // density mode and leaves out a tall object's far end (a guitar's headstock).
  std::vector<glm::vec3> ball, wide;
  const std::size_t n = content_count(model);
  for (std::size_t i = 0; i < n; ++i) {
    const float r = glm::distance(mean_at(model, i), c.mode);
    if (r <= c.radius) ball.push_back(mean_at(model, i));
    if (r <= 1.5f * c.radius) wide.push_back(mean_at(model, i));
  }
  const bool object = c.share >= kObjectShare;
  ContentBox box = object ? content_box(wide, c.up) : ContentBox{};
  if (object && !box.inside.empty()) {  // the whole object, centred, with a margin
    f.orbit_centre = box.centre;
    f.content_points = evenly_picked(box.inside);
    f.framed_share = 1.0;
    f.margin = kFramedMargin;
  } else {  // a scene: its dense core, less the ragged edge
    f.orbit_centre = c.centre;
    f.content_points = evenly_picked(ball);
    f.framed_share = kFramedShare;
    f.margin = 0.0;
  }
  f.scene_scale = glm::distance(first_view_pose(f, 16, 9).position, f.orbit_centre);
  f.source = "content: the densest " + std::to_string(static_cast<int>(std::lround(100.0 * c.share))) +
             "% of the Gaussians, radius " + std::to_string(c.radius) + ", up " +
             (c.up_from_content ? "from its flattest axis" : "-y (no flat layer near the y axis)") +
             (object ? ", an object: framed whole by its percentile box" : ", a scene: its core framed") +
             (stride > 1 ? ", judged by 1 in " + std::to_string(stride) + " of the Gaussians" : std::string());
  return f;
}

CameraPose first_view_pose(const SceneFrame& frame, int width, int height, float fov_deg) {
  if (frame.training_view) return *frame.training_view;
  const glm::vec3 up = glm::normalize(frame.up);
  const glm::vec3 offset = content_view_offset(up);
  CameraPose pose;
  pose.orientation = level_orientation(-offset, up);
  pose.vertical_fov_deg = fov_deg;
  const float tan_v = std::tan(glm::radians(fov_deg) / 2.0f);
  const float tan_h = tan_v * static_cast<float>(std::max(width, 1)) / static_cast<float>(std::max(height, 1));
  pose.position = frame.orbit_centre + framing_distance(frame, pose.orientation, tan_h, tan_v) * offset;
  return pose;
}

std::string find_cameras_file(const std::string& scene_path) {
  namespace fs = std::filesystem;
  const fs::path scene(scene_path);
  std::error_code ec;
  const fs::path beside[] = {scene.parent_path() / (scene.stem().string() + ".cameras.json"),
                             scene.parent_path() / "cameras.json"};
  for (const fs::path& p : beside)
    if (fs::is_regular_file(p, ec)) return p.string();
  // MODEL/point_cloud/iteration_N/point_cloud.ply -> MODEL/cameras.json
  const fs::path iteration = scene.parent_path();
  if (iteration.filename().string().rfind("iteration_", 0) == 0 &&
      iteration.parent_path().filename() == "point_cloud") {
    const fs::path model_cameras = iteration.parent_path().parent_path() / "cameras.json";
    if (fs::is_regular_file(model_cameras, ec)) return model_cameras.string();
  }
  return "";
}

SceneFrame choose_scene_frame(const GaussianModel& model, const std::string& scene_path,
                              const std::string& cameras_flag, std::ostream& log) {
  SceneFrame f;
  const std::string found = cameras_flag.empty() ? find_cameras_file(scene_path) : "";
  if (!cameras_flag.empty()) {
    f = frame_from_cameras(load_inria_cameras(cameras_flag), cameras_flag);
  } else if (!found.empty()) {
    try {
      f = frame_from_cameras(load_inria_cameras(found), found + " (found beside the scene)");
    } catch (const std::exception& e) {
      log << "warning: ignoring the cameras file found beside the scene: " << e.what() << "\n";
      f = frame_from_content(model);
    }
  } else {
    f = frame_from_content(model);
  }
  log << "first view: " << f.source << "; orbit centre (" << f.orbit_centre.x << ", " << f.orbit_centre.y << ", "
      << f.orbit_centre.z << "), up (" << f.up.x << ", " << f.up.y << ", " << f.up.z << "), scene scale "
      << f.scene_scale << "\n";
  return f;
}

}  // namespace catgs::server
