// City-scale scenes by tiling copies of a real scene, and the traces that go with them.
#include "catgs/scene_tiling.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>

#include <glm/gtc/quaternion.hpp>

#include "catgs/cpu_renderer.h"  // parallel_for

namespace catgs {

namespace {

// Quantiles [tail, 1 - tail] of the means projected on `axis`.
std::pair<float, float> quantile_range(const GaussianModel& m, glm::vec3 axis, float tail) {
  const std::size_t n = m.size();
  if (n == 0) throw std::logic_error("quantiles of an empty Gaussian model");
  std::vector<float> v(n);
  for (std::size_t i = 0; i < n; ++i)
    v[i] = axis.x * m.means[3 * i] + axis.y * m.means[3 * i + 1] + axis.z * m.means[3 * i + 2];
  const auto lo_k = static_cast<std::size_t>(static_cast<double>(tail) * static_cast<double>(n - 1));
  const auto hi_k = static_cast<std::size_t>(static_cast<double>(1.0f - tail) * static_cast<double>(n - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(lo_k), v.end());
  const float lo = v[lo_k];
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(hi_k), v.end());
  return {lo, v[hi_k]};
}

// Eigen-decomposition of a symmetric 3x3 matrix (cyclic Jacobi), eigenvectors in columns of V.
void jacobi_eigen(double A[3][3], double V[3][3], double w[3]) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) V[i][j] = i == j ? 1.0 : 0.0;
  for (int sweep = 0; sweep < 50; ++sweep) {
    const double off = A[0][1] * A[0][1] + A[0][2] * A[0][2] + A[1][2] * A[1][2];
    if (off < 1e-30) break;
    for (int p = 0; p < 2; ++p)
      for (int q = p + 1; q < 3; ++q) {
        if (std::fabs(A[p][q]) < 1e-300) continue;
        const double theta = (A[q][q] - A[p][p]) / (2.0 * A[p][q]);
        const double t = (theta >= 0 ? 1.0 : -1.0) / (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0), s = t * c;
        for (int k = 0; k < 3; ++k) {  // A = J^T A J
          const double akp = A[k][p], akq = A[k][q];
          A[k][p] = c * akp - s * akq;
          A[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 3; ++k) {
          const double apk = A[p][k], aqk = A[q][k];
          A[p][k] = c * apk - s * aqk;
          A[q][k] = s * apk + c * aqk;
        }
        for (int k = 0; k < 3; ++k) {
          const double vkp = V[k][p], vkq = V[k][q];
          V[k][p] = c * vkp - s * vkq;
          V[k][q] = s * vkp + c * vkq;
        }
      }
  }
  for (int i = 0; i < 3; ++i) w[i] = A[i][i];
}

// Real SH basis of forward_model.h's sh_to_color (same constants and signs), band l only,
// at unit direction d: out[0 .. 2l].
void sh_band(int l, const double d[3], double* out) {
  const double x = d[0], y = d[1], z = d[2];
  const double C1 = 0.4886025119029199;
  const double xx = x * x, yy = y * y, zz = z * z;
  switch (l) {
    case 1:
      out[0] = -C1 * y; out[1] = C1 * z; out[2] = -C1 * x;
      break;
    case 2:
      out[0] = 1.0925484305920792 * x * y;
      out[1] = -1.0925484305920792 * y * z;
      out[2] = 0.31539156525252005 * (2.0 * zz - xx - yy);
      out[3] = -1.0925484305920792 * x * z;
      out[4] = 0.5462742152960396 * (xx - yy);
      break;
    case 3:
      out[0] = -0.5900435899266435 * y * (3.0 * xx - yy);
      out[1] = 2.890611442640554 * x * y * z;
      out[2] = -0.4570457994644658 * y * (4.0 * zz - xx - yy);
      out[3] = 0.3731763325901154 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
      out[4] = -0.4570457994644658 * x * (4.0 * zz - xx - yy);
      out[5] = 1.445305721320277 * z * (xx - yy);
      out[6] = -0.5900435899266435 * x * (xx - 3.0 * yy);
      break;
    default:
      break;
  }
}

// Solves A X = B for X (n x n, n <= 7, several right-hand sides) by Gaussian elimination with
// partial pivoting; A and B are overwritten.
void solve(int n, double A[7][7], double B[7][7]) {
  for (int c = 0; c < n; ++c) {
    int piv = c;
    for (int r = c + 1; r < n; ++r)
      if (std::fabs(A[r][c]) > std::fabs(A[piv][c])) piv = r;
    std::swap(A[c], A[piv]);
    std::swap(B[c], B[piv]);
    for (int r = 0; r < n; ++r) {
      if (r == c) continue;
      const double f = A[r][c] / A[c][c];
      for (int k = 0; k < n; ++k) {
        A[r][k] -= f * A[c][k];
        B[r][k] -= f * B[c][k];
      }
    }
  }
  for (int r = 0; r < n; ++r)
    for (int k = 0; k < n; ++k) B[r][k] /= A[r][r];
}

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

Bounds robust_bounds(const GaussianModel& model, float tail) {
  Bounds b;
  for (int a = 0; a < 3; ++a) {
    glm::vec3 axis(0.0f);
    axis[a] = 1.0f;
    const auto [lo, hi] = quantile_range(model, axis, tail);
    b.min[a] = lo;
    b.max[a] = hi;
  }
  return b;
}

glm::vec3 estimate_up(const GaussianModel& model) {
  const Bounds rb = robust_bounds(model, 0.02f);
  double mean[3] = {0, 0, 0}, C[3][3] = {};
  std::size_t count = 0;
  auto inside = [&](std::size_t i) {
    for (int a = 0; a < 3; ++a)
      if (model.means[3 * i + a] < rb.min[a] || model.means[3 * i + a] > rb.max[a]) return false;
    return true;
  };
  for (std::size_t i = 0; i < model.size(); ++i)
    if (inside(i)) {
      for (int a = 0; a < 3; ++a) mean[a] += model.means[3 * i + a];
      ++count;
    }
  if (count < 3) return {0.0f, -1.0f, 0.0f};
  for (double& m : mean) m /= static_cast<double>(count);
  for (std::size_t i = 0; i < model.size(); ++i)
    if (inside(i))
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
          C[a][b] += (model.means[3 * i + a] - mean[a]) * (model.means[3 * i + b] - mean[b]);
  double V[3][3], w[3];
  jacobi_eigen(C, V, w);
  int k = 0;
  for (int a = 1; a < 3; ++a)
    if (w[a] < w[k]) k = a;
  glm::vec3 up(static_cast<float>(V[0][k]), static_cast<float>(V[1][k]), static_cast<float>(V[2][k]));
  up = glm::normalize(up);
  double m3 = 0.0;  // third central moment along up
  for (std::size_t i = 0; i < model.size(); ++i)
    if (inside(i)) {
      double h = 0.0;
      for (int a = 0; a < 3; ++a) h += (model.means[3 * i + a] - mean[a]) * up[a];
      m3 += h * h * h;
    }
  return m3 < 0.0 ? -up : up;
}

void scale_scene(GaussianModel& model, float s) {
  if (!(s > 0.0f) || !std::isfinite(s))
    throw std::invalid_argument("scale_scene: scale must be positive and finite");
  const float log_s = std::log(s);
  for (float& v : model.means) v *= s;
  for (float& v : model.log_scales) v += log_s;
}

ShRotation make_sh_rotation(int degree, const glm::mat3& R) {
  ShRotation rot;
  rot.degree = degree;
  constexpr int kSamples = 64;  // Fibonacci sphere: well spread, deterministic
  std::array<std::array<double, 3>, kSamples> dirs{}, rotated{};
  const glm::dmat3 Rt = glm::transpose(glm::dmat3(R));
  for (int k = 0; k < kSamples; ++k) {
    const double z = 1.0 - (2.0 * k + 1.0) / kSamples;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = k * 2.399963229728653;
    dirs[static_cast<std::size_t>(k)] = {r * std::cos(phi), r * std::sin(phi), z};
    const glm::dvec3 d(r * std::cos(phi), r * std::sin(phi), z);
    const glm::dvec3 q = Rt * d;  // the old direction that now looks along d
    rotated[static_cast<std::size_t>(k)] = {q.x, q.y, q.z};
  }
  for (int l = 1; l <= degree; ++l) {
    const int m = 2 * l + 1;
    double AtA[7][7] = {}, AtB[7][7] = {};
    for (int k = 0; k < kSamples; ++k) {
      double a[7], b[7];
      sh_band(l, dirs[static_cast<std::size_t>(k)].data(), a);
      sh_band(l, rotated[static_cast<std::size_t>(k)].data(), b);
      for (int i = 0; i < m; ++i)
        for (int j = 0; j < m; ++j) {
          AtA[i][j] += a[i] * a[j];
          AtB[i][j] += a[i] * b[j];
        }
    }
    solve(m, AtA, AtB);  // AtB = M: c' = M c
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < m; ++j) rot.band[l][i][j] = AtB[i][j];
  }
  return rot;
}

void ShRotation::apply(float* sh) const {
  for (int l = 1; l <= degree; ++l) {
    const int m = 2 * l + 1, first = l * l;
    for (int c = 0; c < 3; ++c) {
      double in[7], out[7];
      for (int j = 0; j < m; ++j) in[j] = sh[(first + j) * 3 + c];
      for (int i = 0; i < m; ++i) {
        out[i] = 0.0;
        for (int j = 0; j < m; ++j) out[i] += band[l][i][j] * in[j];
      }
      for (int i = 0; i < m; ++i) sh[(first + i) * 3 + c] = static_cast<float>(out[i]);
    }
  }
}

void rotate_sh(int degree, float* sh, const glm::mat3& R) { make_sh_rotation(degree, R).apply(sh); }

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
  const auto [a0, a1] = quantile_range(base, L.axis_a, 0.02f);
  const auto [b0, b1] = quantile_range(base, L.axis_b, 0.02f);
  const auto [u0, u1] = quantile_range(base, L.up, 0.02f);
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
  cpu::parallel_for(copies * chunks_per_copy, 1, [&](std::size_t task) {
    const std::size_t c = task / chunks_per_copy;
    const std::size_t begin = (task % chunks_per_copy) * kChunk, end = std::min(n, begin + kChunk);
    const glm::vec3 offset = L.spacing * (static_cast<float>(L.cells[c].x) * L.axis_a +
                                          static_cast<float>(L.cells[c].y) * L.axis_b);
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
      const glm::quat q2 = Q[c] * q;  // the Gaussian's frame turns with the copy
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
                         float distance_extents, double rate_hz, double seconds_per_view,
                         int width, int height) {
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

std::vector<uint32_t> morton_order(const GaussianModel& m) {
  const std::size_t n = m.size();
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  if (n == 0) return order;
  const Bounds rb = robust_bounds(m, 0.001f);
  auto spread = [](uint64_t v) {  // 21 bits -> every third bit
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffull;
    v = (v | v << 16) & 0x1f0000ff0000ffull;
    v = (v | v << 8) & 0x100f00f00f00f00full;
    v = (v | v << 4) & 0x10c30c30c30c30c3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
  };
  std::vector<uint64_t> code(n);
  for (std::size_t i = 0; i < n; ++i) {
    uint64_t c = 0;
    for (int a = 0; a < 3; ++a) {
      const float range = rb.max[a] - rb.min[a];
      float t = range > 0.0f ? (m.means[3 * i + a] - rb.min[a]) / range : 0.0f;
      t = std::clamp(t, 0.0f, 1.0f);
      c |= spread(static_cast<uint64_t>(t * 2097151.0f)) << a;
    }
    code[i] = c;
  }
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return code[a] < code[b]; });
  return order;
}

GaussianModel permuted(const GaussianModel& m, const std::vector<uint32_t>& order) {
  if (order.size() != m.size()) throw std::invalid_argument("permuted: order size differs from the model");
  GaussianModel out;
  out.name = m.name;
  out.sh_degree = m.sh_degree;
  out.resize(m.size());
  const std::size_t K3 = static_cast<std::size_t>(m.sh_coeffs()) * 3;
  for (std::size_t i = 0; i < order.size(); ++i) {
    const std::size_t j = order[i];
    if (j >= m.size()) throw std::invalid_argument("permuted: index out of range");
    std::copy_n(&m.means[3 * j], 3, &out.means[3 * i]);
    std::copy_n(&m.log_scales[3 * j], 3, &out.log_scales[3 * i]);
    std::copy_n(&m.rotations[4 * j], 4, &out.rotations[4 * i]);
    out.opacity_logits[i] = m.opacity_logits[j];
    std::copy_n(&m.sh[j * K3], K3, &out.sh[i * K3]);
  }
  return out;
}

}  // namespace catgs
