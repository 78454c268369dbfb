#include "shown/page_reprojection.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace catgs::shown {

namespace {

constexpr double kPi = 3.141592653589793;  // Math.PI

// JS's Math.max / Math.min: NaN if either is NaN, and +0 above -0 (std::max and std::min return
// their first argument on NaN or equal zeros; edgeFill's clamps must agree on those too).
double js_max(double a, double b) {
  if (std::isnan(a) || std::isnan(b)) return std::numeric_limits<double>::quiet_NaN();
  if (a == 0.0 && b == 0.0) return std::signbit(a) ? b : a;
  return a > b ? a : b;
}

double js_min(double a, double b) {
  if (std::isnan(a) || std::isnan(b)) return std::numeric_limits<double>::quiet_NaN();
  if (a == 0.0 && b == 0.0) return std::signbit(a) ? a : b;
  return a < b ? a : b;
}

// JS's Math.round for the finite, non-negative values display.js rounds: half up, exactly
// (floor(x + 0.5) misrounds 0.49999999999999994).
double js_round(double x) {
  const double f = std::floor(x);
  return x - f >= 0.5 ? f + 1.0 : f;
}

// camera.js's vdot and vsub, in its order of operations.
double vdot(const glm::dvec3& a, const glm::dvec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

glm::dvec3 vsub(const glm::dvec3& a, const glm::dvec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }

glm::dvec3 vcross(const glm::dvec3& a, const glm::dvec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

glm::dvec3 camera_forward(const glm::dquat& q) { return qrotate(q, {0.0, 0.0, 1.0}); }

// reproject.js matVec: rows of m dotted with v.
glm::dvec3 mat_vec(const std::array<glm::dvec3, 3>& m, const glm::dvec3& v) {
  return {vdot(m[0], v), vdot(m[1], v), vdot(m[2], v)};
}

// reproject.js's local mul: a b, each element summed left to right.
Mat3 mul(const Mat3& a, const Mat3& b) {
  Mat3 r{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
  return r;
}

void check_rgba8(const Image& img, const char* what) {
  if (img.width < 1 || img.height < 1)
    throw std::invalid_argument(std::string(what) + ": size " + std::to_string(img.width) + "x" +
                                std::to_string(img.height) + " is empty");
  if (img.rgba8.size() != static_cast<std::size_t>(img.width) * img.height * 4)
    throw std::invalid_argument(std::string(what) + ": rgba8 holds " + std::to_string(img.rgba8.size()) +
                                " bytes, not width * height * 4");
}

Image blank_rgba8(int width, int height) {
  Image img;
  img.width = width;
  img.height = height;
  img.rgba8.assign(static_cast<std::size_t>(width) * height * 4, 255);
  return img;
}

uint8_t to_byte(double v) { return static_cast<uint8_t>(js_min(js_max(std::floor(v + 0.5), 0.0), 255.0)); }

// One side of edgeFill's outline: from a along d (to the next corner), |d|^2.
struct Edge {
  double ax, ay, dx, dy, len2;
};

// edgeFill's outline: H applied to the frame's corners (0,0), (w,0), (w,h), (0,h) in that order,
// or nullopt when one is behind.
std::optional<std::array<Edge, 4>> outline_edges(const Mat3& H, int width, int height) {
  const double w = width, h = height;
  const double corners[4][2] = {{0.0, 0.0}, {w, 0.0}, {w, h}, {0.0, h}};
  std::array<std::array<double, 2>, 4> quad{};
  for (int k = 0; k < 4; ++k) {
    const auto q = apply_homography(H, corners[k][0], corners[k][1]);
    if (!q) return std::nullopt;
    quad[k] = *q;
  }
  std::array<Edge, 4> edges{};
  for (int k = 0; k < 4; ++k) {
    const auto& a = quad[k];
    const auto& b = quad[(k + 1) % 4];
    const double dx = b[0] - a[0], dy = b[1] - a[1];
    edges[k] = {a[0], a[1], dx, dy, dx * dx + dy * dy};
  }
  return edges;
}

// edgeFill's orientation: the sign of the outline's (doubled) signed area, summed as the page sums
// it ((acc + x_a y_b) - x_b y_a with y_b = a.y + d.y, not b's own y).
double outline_sign(const std::array<Edge, 4>& edges) {
  double acc = 0.0;
  for (const Edge& e : edges) acc = acc + e.ax * (e.ay + e.dy) - (e.ax + e.dx) * e.ay;
  return acc >= 0.0 ? 1.0 : -1.0;
}

bool outside(const std::array<Edge, 4>& edges, double sign, double x, double y) {
  for (const Edge& e : edges)
    if (sign * (e.dx * (y - e.ay) - e.dy * (x - e.ax)) < 0.0) return true;
  return false;
}

// The outline's point nearest (x, y) (the first edge's on ties, as the page's strict <); (x, y)
// itself when every distance is NaN.
std::array<double, 2> nearest_on_outline(const std::array<Edge, 4>& edges, double x, double y) {
  double best = std::numeric_limits<double>::infinity();
  double nx = x, ny = y;
  for (const Edge& e : edges) {
    const double t = e.len2 > 0.0 ? js_min(js_max(((x - e.ax) * e.dx + (y - e.ay) * e.dy) / e.len2, 0.0), 1.0) : 0.0;
    const double px = e.ax + t * e.dx;
    const double py = e.ay + t * e.dy;
    const double dist2 = (px - x) * (px - x) + (py - y) * (py - y);
    if (dist2 < best) {
      best = dist2;
      nx = px;
      ny = py;
    }
  }
  return {nx, ny};
}

// edgeFill's source index: Math.min(Math.max(Math.floor(c), 0), n - 1) || 0 (NaN and -0 give 0).
int clamp_index(double c, int n) {
  const double v = js_min(js_max(std::floor(c), 0.0), static_cast<double>(n - 1));
  return std::isnan(v) || v == 0.0 ? 0 : static_cast<int>(v);
}

// Horizontal or vertical area-average weights: for each of `to` target cells over `from` source
// cells, the (source index, weight) pairs it covers; the weights of a cell sum to 1.
std::vector<std::vector<std::pair<int, double>>> area_weights(int from, int to) {
  std::vector<std::vector<std::pair<int, double>>> w(static_cast<std::size_t>(to));
  const double scale = static_cast<double>(from) / to;
  for (int i = 0; i < to; ++i) {
    const double lo = i * scale, hi = (i + 1) * scale;
    for (int k = static_cast<int>(std::floor(lo)); k < from && k < hi; ++k) {
      const double cover = js_min(hi, k + 1.0) - js_max(lo, static_cast<double>(k));
      if (cover > 0.0) w[static_cast<std::size_t>(i)].push_back({k, cover / scale});
    }
  }
  return w;
}

// The shown canvas's inverse mapping: the canvas point under screen point (x, y), or nullopt when
// the canvas's plane does not reach it (homogeneous w not > 0: past the moved frame's horizon).
std::optional<std::array<double, 2>> canvas_point(const Mat3& Hi, double x, double y) {
  const double W = Hi[2][0] * x + Hi[2][1] * y + Hi[2][2];
  if (!(W > 0.0)) return std::nullopt;
  return std::array<double, 2>{(Hi[0][0] * x + Hi[0][1] * y + Hi[0][2]) / W,
                               (Hi[1][0] * x + Hi[1][1] * y + Hi[1][2]) / W};
}

// The backdrop as display.js leaves it: the frame shrunk to backdrop size, edgeFill'ed by H.
// nullopt when edgeFill refuses: with every corner in front only for a singular H (a plane seen
// edge-on), whose CSS matrix the browser cannot show either; the plain frame stands for it.
std::optional<Image> backdrop_of(const Image& frame, const Mat3& H) {
  const Size b = backdrop_size(frame.width, frame.height);
  const Image small = shrink_area_average(frame, b.width, b.height);
  Image out = blank_rgba8(b.width, b.height);
  if (!edge_fill(H, frame.width, frame.height, small, out)) return std::nullopt;
  return out;
}

void put_rgb(Image& img, int i, int j, const std::array<double, 3>& c) {
  const std::size_t o = (static_cast<std::size_t>(j) * img.width + i) * 4;
  for (int k = 0; k < 3; ++k) img.rgba8[o + k] = to_byte(c[static_cast<std::size_t>(k)]);
  img.rgba8[o + 3] = 255;
}

}  // namespace

PagePose page_pose_of(const Camera& c) {
  const glm::vec3 p = c.position();
  const glm::quat q = c.orientation();
  PagePose pose;
  pose.position = glm::dvec3(p.x, p.y, p.z);
  pose.orientation = glm::dquat(q.w, q.x, q.y, q.z);
  pose.fov_deg = c.vertical_fov_deg();
  return pose;
}

bool same_pose(const PagePose& a, const PagePose& b) {
  return a.fov_deg == b.fov_deg && a.position.x == b.position.x && a.position.y == b.position.y &&
         a.position.z == b.position.z && a.orientation.w == b.orientation.w && a.orientation.x == b.orientation.x &&
         a.orientation.y == b.orientation.y && a.orientation.z == b.orientation.z;
}

Intrinsics intrinsics_for(double fov_deg, int width, int height) {
  // (fovDeg * Math.PI) / 180 / 2, in the page's order.
  const double f = height / (2.0 * std::tan(fov_deg * kPi / 180.0 / 2.0));
  return {f, f, width / 2.0, height / 2.0};
}

glm::dvec3 qrotate(const glm::dquat& q, const glm::dvec3& v) {
  const glm::dvec3 u(q.x, q.y, q.z);
  const glm::dvec3 c = vcross(u, v);
  const glm::dvec3 t(c.x * 2.0, c.y * 2.0, c.z * 2.0);
  const glm::dvec3 tw(t.x * q.w, t.y * q.w, t.z * q.w);
  const glm::dvec3 s(v.x + tw.x, v.y + tw.y, v.z + tw.z);
  const glm::dvec3 ut = vcross(u, t);
  return {s.x + ut.x, s.y + ut.y, s.z + ut.z};
}

Mat3 plane_reprojection(const PagePose& from, const PagePose& to, double plane_depth, int width, int height) {
  const Intrinsics k1 = intrinsics_for(from.fov_deg, width, height);
  const Intrinsics k2 = intrinsics_for(to.fov_deg, width, height);
  // W2: world -> `to` camera, rows = to's axes in world (reproject.js worldToCamera).
  const std::array<glm::dvec3, 3> w2 = {qrotate(to.orientation, {1.0, 0.0, 0.0}),
                                        qrotate(to.orientation, {0.0, 1.0, 0.0}),
                                        qrotate(to.orientation, {0.0, 0.0, 1.0})};
  // R = W2 W1^T: its columns are from's axes seen from `to`; t = W2 (p1 - p2).
  const glm::dquat& q1 = from.orientation;
  const std::array<glm::dvec3, 3> axes1 = {qrotate(q1, {1.0, 0.0, 0.0}), qrotate(q1, {0.0, 1.0, 0.0}),
                                           camera_forward(q1)};
  std::array<glm::dvec3, 3> cols{};
  for (int j = 0; j < 3; ++j) cols[static_cast<std::size_t>(j)] = mat_vec(w2, axes1[static_cast<std::size_t>(j)]);
  const glm::dvec3 t = mat_vec(w2, vsub(from.position, to.position));
  // A = R + t n^T / d with n = (0, 0, 1): only the third column changes.
  Mat3 A{};
  for (int i = 0; i < 3; ++i) A[i] = {cols[0][i], cols[1][i], cols[2][i] + t[i] / plane_depth};
  const Mat3 k_inv = {{{1.0 / k1.fx, 0.0, -k1.cx / k1.fx}, {0.0, 1.0 / k1.fy, -k1.cy / k1.fy}, {0.0, 0.0, 1.0}}};
  const Mat3 K2 = {{{k2.fx, 0.0, k2.cx}, {0.0, k2.fy, k2.cy}, {0.0, 0.0, 1.0}}};
  return mul(mul(K2, A), k_inv);
}

std::optional<std::array<double, 2>> apply_homography(const Mat3& H, double x, double y) {
  const double w = H[2][0] * x + H[2][1] * y + H[2][2];
  if (!(w > 1e-9)) return std::nullopt;
  return std::array<double, 2>{(H[0][0] * x + H[0][1] * y + H[0][2]) / w, (H[1][0] * x + H[1][1] * y + H[1][2]) / w};
}

double plane_depth_for(const PagePose& pose, const glm::dvec3& target, double fallback) {
  const double d = vdot(vsub(target, pose.position), camera_forward(pose.orientation));
  return d > 1e-6 ? d : fallback;
}

std::optional<Mat3> invert3(const Mat3& m) {
  const double a = m[0][0], b = m[0][1], c = m[0][2];
  const double d = m[1][0], e = m[1][1], f = m[1][2];
  const double g = m[2][0], h = m[2][1], i = m[2][2];
  const double A = e * i - f * h;
  const double B = f * g - d * i;
  const double C = d * h - e * g;
  const double det = a * A + b * B + c * C;
  if (!(std::abs(det) > 1e-300)) return std::nullopt;
  const double s = 1.0 / det;
  return Mat3{{{A * s, (c * h - b * i) * s, (b * f - c * e) * s},
               {B * s, (a * i - c * g) * s, (c * d - a * f) * s},
               {C * s, (b * g - a * h) * s, (a * e - b * d) * s}}};
}

Mat3 css_homography(const Mat3& H) {
  // cssTransform with sx = sy = 1: m = H, each element / m[2][2], then 9 significant digits.
  const double s = H[2][2];
  Mat3 r{};
  char buf[40];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      std::snprintf(buf, sizeof buf, "%.9g", H[i][j] / s);
      r[i][j] = std::strtod(buf, nullptr);
    }
  return r;
}

bool edge_fill(const Mat3& H, int width, int height, const Image& src, Image& out) {
  if (width < 1 || height < 1) throw std::invalid_argument("edge_fill: the frame's size is empty");
  check_rgba8(src, "edge_fill src");
  if (out.width < 1 || out.height < 1) throw std::invalid_argument("edge_fill: out's size is empty");
  const auto Hi = invert3(H);
  const auto edges = outline_edges(H, width, height);
  if (!Hi || !edges) return false;
  const double sign = outline_sign(*edges);
  const double sx = static_cast<double>(src.width) / width;
  const double sy = static_cast<double>(src.height) / height;
  const double ox = static_cast<double>(width) / out.width;
  const double oy = static_cast<double>(height) / out.height;
  out.rgba8.resize(static_cast<std::size_t>(out.width) * out.height * 4);
  const Mat3& M = *Hi;
  for (int j = 0; j < out.height; ++j) {
    for (int i = 0; i < out.width; ++i) {
      double x = (i + 0.5) * ox;
      double y = (j + 0.5) * oy;
      if (outside(*edges, sign, x, y)) {
        const auto n = nearest_on_outline(*edges, x, y);
        x = n[0];
        y = n[1];
      }
      const double W = M[2][0] * x + M[2][1] * y + M[2][2];
      const double u = (M[0][0] * x + M[0][1] * y + M[0][2]) / W;
      const double v = (M[1][0] * x + M[1][1] * y + M[1][2]) / W;
      const int si = clamp_index(u * sx, src.width);
      const int sj = clamp_index(v * sy, src.height);
      const std::size_t s = (static_cast<std::size_t>(sj) * src.width + si) * 4;
      const std::size_t o = (static_cast<std::size_t>(j) * out.width + i) * 4;
      out.rgba8[o] = src.rgba8[s];
      out.rgba8[o + 1] = src.rgba8[s + 1];
      out.rgba8[o + 2] = src.rgba8[s + 2];
      out.rgba8[o + 3] = 255;
    }
  }
  return true;
}

Size backdrop_size(int width, int height) {
  const double k = js_min(1.0, 256.0 / js_max(width, height));
  return {static_cast<int>(js_max(1.0, js_round(width * k))), static_cast<int>(js_max(1.0, js_round(height * k)))};
}

Image shrink_area_average(const Image& frame, int target_width, int target_height) {
  check_rgba8(frame, "shrink_area_average frame");
  if (target_width < 1 || target_height < 1) throw std::invalid_argument("shrink_area_average: empty target size");
  Image out = blank_rgba8(target_width, target_height);
  if (target_width == frame.width && target_height == frame.height) {
    out.rgba8 = frame.rgba8;
    return out;
  }
  const auto wx = area_weights(frame.width, target_width);
  const auto wy = area_weights(frame.height, target_height);
  // Rows first (frame.height x target_width), then columns.
  std::vector<double> rows(static_cast<std::size_t>(frame.height) * target_width * 3, 0.0);
  for (int y = 0; y < frame.height; ++y)
    for (int i = 0; i < target_width; ++i)
      for (const auto& [x, w] : wx[static_cast<std::size_t>(i)])
        for (int c = 0; c < 3; ++c)
          rows[(static_cast<std::size_t>(y) * target_width + i) * 3 + c] +=
              w * frame.rgba8[(static_cast<std::size_t>(y) * frame.width + x) * 4 + c];
  for (int j = 0; j < target_height; ++j)
    for (int i = 0; i < target_width; ++i) {
      std::array<double, 3> sum{};
      for (const auto& [y, w] : wy[static_cast<std::size_t>(j)])
        for (int c = 0; c < 3; ++c) sum[c] += w * rows[(static_cast<std::size_t>(y) * target_width + i) * 3 + c];
      put_rgb(out, i, j, sum);
    }
  return out;
}

std::array<double, 3> sample_bilinear(const Image& img, double x, double y) {
  const double fx = x - 0.5, fy = y - 0.5;
  const double x0 = std::floor(fx), y0 = std::floor(fy);
  const double tx = fx - x0, ty = fy - y0;
  auto clampi = [](double v, int n) { return static_cast<std::size_t>(v < 0.0 ? 0.0 : (v > n - 1 ? n - 1 : v)); };
  const std::size_t xa = clampi(x0, img.width), xb = clampi(x0 + 1.0, img.width);
  const std::size_t ya = clampi(y0, img.height), yb = clampi(y0 + 1.0, img.height);
  const auto at = [&](std::size_t xi, std::size_t yi, int c) {
    return static_cast<double>(img.rgba8[(yi * img.width + xi) * 4 + c]);
  };
  std::array<double, 3> r{};
  for (int c = 0; c < 3; ++c) {
    const double top = at(xa, ya, c) + tx * (at(xb, ya, c) - at(xa, ya, c));
    const double bottom = at(xa, yb, c) + tx * (at(xb, yb, c) - at(xa, yb, c));
    r[c] = top + ty * (bottom - top);
  }
  return r;
}

Image shown_picture(const Image& frame, const PagePose& from, const PagePose& to, double plane_depth) {
  check_rgba8(frame, "shown_picture frame");
  const int w = frame.width, h = frame.height;
  Image plain;
  plain.width = w;
  plain.height = h;
  plain.rgba8 = frame.rgba8;
  if (same_pose(from, to)) return plain;
  const Mat3 H = plane_reprojection(from, to, plane_depth, w, h);
  // ViewDisplay.reproject: no transform when a corner falls behind the new camera.
  const double cw = w, ch = h;
  const std::array<std::array<double, 2>, 4> corners = {{{0.0, 0.0}, {cw, 0.0}, {0.0, ch}, {cw, ch}}};
  for (const auto& c : corners)
    if (!apply_homography(H, c[0], c[1])) return plain;
  const auto Hi = invert3(css_homography(H));
  const auto backdrop = backdrop_of(frame, H);
  if (!Hi || !backdrop) return plain;
  Image out = blank_rgba8(w, h);
  const double bx = static_cast<double>(backdrop->width) / w, by = static_cast<double>(backdrop->height) / h;
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const double x = i + 0.5, y = j + 0.5;
      const auto c = canvas_point(*Hi, x, y);
      const bool on_canvas = c && (*c)[0] >= 0.0 && (*c)[0] <= w && (*c)[1] >= 0.0 && (*c)[1] <= h;
      put_rgb(out, i, j,
              on_canvas ? sample_bilinear(frame, (*c)[0], (*c)[1]) : sample_bilinear(*backdrop, x * bx, y * by));
    }
  return out;
}

}  // namespace catgs::shown
