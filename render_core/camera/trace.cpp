// Traces: INRIA cameras.json, interpolation, generators and our text trace format.
#include "camera/trace.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

namespace catgs {

std::vector<Camera> load_inria_cameras(const std::string& path, int width, int height) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open file");
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(in);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": malformed JSON: " + e.what());
  }
  if (!doc.is_array() || doc.empty()) throw std::runtime_error(path + ": expected a non-empty JSON list of cameras");
  std::vector<Camera> cams;
  for (std::size_t k = 0; k < doc.size(); ++k) {
    const auto& j = doc[k];
    try {
      Camera c;
      c.width = j.at("width").get<int>();
      c.height = j.at("height").get<int>();
      c.fx = j.at("fx").get<float>();
      c.fy = j.at("fy").get<float>();
      glm::vec3 pos;
      glm::mat3 c2w;  // rows of the JSON = rows of camera-to-world
      for (int r = 0; r < 3; ++r) {
        pos[r] = j.at("position").at(r).get<float>();
        for (int col = 0; col < 3; ++col) c2w[col][r] = j.at("rotation").at(r).at(col).get<float>();
      }
      if (c.width < 1 || c.height < 1 || !(c.fx > 0) || !(c.fy > 0) || !std::isfinite(c.fx) || !std::isfinite(c.fy))
        throw std::runtime_error("bad size or focal length");
      for (int r = 0; r < 3; ++r) {
        if (!std::isfinite(pos[r])) throw std::runtime_error("non-finite position");
        for (int col = 0; col < 3; ++col)
          if (!std::isfinite(c2w[col][r])) throw std::runtime_error("non-finite rotation");
      }
      c.cx = static_cast<float>(c.width) / 2.0f;
      c.cy = static_cast<float>(c.height) / 2.0f;
      c.R = glm::transpose(c2w);
      c.t = -(c.R * pos);
      cams.push_back(width > 0 && height > 0 ? c.rescaled(width, height) : c);
    } catch (const std::exception& e) {
      throw std::runtime_error(path + ": camera entry " + std::to_string(k) + ": " + e.what());
    }
  }
  return cams;
}

namespace {

// Centripetal Catmull-Rom (alpha = 0.5, Barry-Goldman pyramid) between p1 and p2, u in [0, 1].
glm::vec3 centripetal_catmull_rom(glm::vec3 p0, glm::vec3 p1, glm::vec3 p2, glm::vec3 p3, float u) {
  auto knot = [](glm::vec3 a, glm::vec3 b) { return std::fmax(std::sqrt(glm::distance(a, b)), 1e-4f); };
  const float t0 = 0.0f, t1 = t0 + knot(p0, p1), t2 = t1 + knot(p1, p2), t3 = t2 + knot(p2, p3);
  const float t = t1 + u * (t2 - t1);
  const glm::vec3 a1 = ((t1 - t) * p0 + (t - t0) * p1) / (t1 - t0);
  const glm::vec3 a2 = ((t2 - t) * p1 + (t - t1) * p2) / (t2 - t1);
  const glm::vec3 a3 = ((t3 - t) * p2 + (t - t2) * p3) / (t3 - t2);
  const glm::vec3 b1 = ((t2 - t) * a1 + (t - t0) * a2) / (t2 - t0);
  const glm::vec3 b2 = ((t3 - t) * a2 + (t - t1) * a3) / (t3 - t1);
  return ((t2 - t) * b1 + (t - t1) * b2) / (t2 - t1);
}

Camera camera_at(const glm::vec3& eye, const glm::quat& c2w, const Camera& intrinsics) {
  Camera c = intrinsics;
  c.R = glm::transpose(glm::mat3_cast(c2w));
  c.t = -(c.R * eye);
  return c;
}

// Camera-to-world rotation looking from eye to target with world `up` (OpenCV axes).
glm::quat look_rotation(glm::vec3 eye, glm::vec3 target, glm::vec3 up) {
  const glm::vec3 z = glm::normalize(target - eye);
  glm::vec3 x = glm::cross(z, up);
  if (glm::length(x) < 1e-6f) x = glm::cross(z, glm::vec3(1, 0, 0));
  x = glm::normalize(x);
  const glm::vec3 y = glm::cross(z, x);
  return glm::normalize(glm::quat_cast(glm::mat3(x, y, z)));
}

std::size_t sample_count(const GeneratorParams& p) {
  if (!(p.rate_hz > 0) || !(p.duration_s >= 0)) throw std::invalid_argument("bad trace rate or duration");
  return static_cast<std::size_t>(std::llround(p.duration_s * p.rate_hz)) + 1;
}

template <typename PoseAt>  // PoseAt(s in [0,1]) -> (eye, c2w)
Trace generate(const GeneratorParams& p, PoseAt pose_at) {
  const Camera proto = Camera::from_pose({0, 0, 0}, glm::quat(1, 0, 0, 0), p.fov_deg, p.width, p.height);
  const std::size_t n = sample_count(p);
  Trace trace(n);
  for (std::size_t i = 0; i < n; ++i) {
    const float s = n > 1 ? static_cast<float>(i) / static_cast<float>(n - 1) : 0.0f;
    const auto [eye, rot] = pose_at(s);
    trace[i] = {static_cast<double>(i) / p.rate_hz, camera_at(eye, rot, proto)};
  }
  return trace;
}

// Two unit vectors spanning the plane perpendicular to `up`.
void plane_basis(glm::vec3 up, glm::vec3* a, glm::vec3* b) {
  const glm::vec3 u = glm::normalize(up);
  *a = glm::normalize(glm::cross(u, std::fabs(u.x) < 0.9f ? glm::vec3(1, 0, 0) : glm::vec3(0, 0, 1)));
  *b = glm::cross(u, *a);
}

}  // namespace

Trace interpolate_views(const std::vector<Camera>& keys, double rate_hz, double seconds_per_view) {
  if (keys.size() < 2) throw std::invalid_argument("interpolation needs at least 2 key views");
  if (!(rate_hz > 0) || !(seconds_per_view > 0))
    throw std::invalid_argument("interpolation rate and seconds per view must be positive");
  const std::size_t segments = keys.size() - 1;
  const auto per_segment = static_cast<std::size_t>(std::llround(seconds_per_view * rate_hz));
  if (per_segment == 0) throw std::invalid_argument("seconds_per_view * rate_hz < 1");
  std::vector<glm::vec3> pos(keys.size());
  std::vector<glm::quat> rot(keys.size());
  for (std::size_t k = 0; k < keys.size(); ++k) {
    pos[k] = keys[k].position();
    rot[k] = keys[k].orientation();
  }
  Trace trace;
  trace.reserve(segments * per_segment + 1);
  for (std::size_t s = 0; s < segments; ++s) {
    const glm::vec3 p1 = pos[s], p2 = pos[s + 1];
    const glm::vec3 p0 = s > 0 ? pos[s - 1] : 2.0f * p1 - p2;  // reflected end points
    const glm::vec3 p3 = s + 2 < pos.size() ? pos[s + 2] : 2.0f * p2 - p1;
    const std::size_t steps = per_segment + (s + 1 == segments ? 1 : 0);
    for (std::size_t i = 0; i < steps; ++i) {
      const float u = static_cast<float>(i) / static_cast<float>(per_segment);
      Camera c = keys[s];
      c.fx += u * (keys[s + 1].fx - keys[s].fx);
      c.fy += u * (keys[s + 1].fy - keys[s].fy);
      c.cx += u * (keys[s + 1].cx - keys[s].cx);
      c.cy += u * (keys[s + 1].cy - keys[s].cy);
      const glm::vec3 eye = centripetal_catmull_rom(p0, p1, p2, p3, u);
      const double time = static_cast<double>(trace.size()) / rate_hz;
      trace.push_back({time, camera_at(eye, glm::slerp(rot[s], rot[s + 1], u), c)});
    }
  }
  return trace;
}

Trace resample_trace(const Trace& trace, double rate_hz) {
  if (trace.empty()) throw std::invalid_argument("resampling an empty trace");
  if (!(rate_hz > 0)) throw std::invalid_argument("resampling rate must be positive");
  constexpr double kSnap = 1e-6;  // seconds: a sample this close to a trace camera is that camera
  const double t0 = trace.front().time_s, span = trace.back().time_s - t0;
  const auto n = static_cast<std::size_t>(std::floor(span * rate_hz + kSnap * rate_hz)) + 1;
  Trace out;
  out.reserve(n);
  std::size_t i = 0;  // trace[i].time_s <= t < trace[i + 1].time_s
  for (std::size_t k = 0; k < n; ++k) {
    const double t = t0 + static_cast<double>(k) / rate_hz;
    while (i + 1 < trace.size() && trace[i + 1].time_s <= t + kSnap) ++i;
    const TimedCamera& a = trace[i];
    if (i + 1 == trace.size() || t - a.time_s <= kSnap) {
      out.push_back({t, a.camera});
      continue;
    }
    const TimedCamera& b = trace[i + 1];
    const float u = static_cast<float>((t - a.time_s) / (b.time_s - a.time_s));
    Camera c = a.camera;
    c.fx += u * (b.camera.fx - c.fx);
    c.fy += u * (b.camera.fy - c.fy);
    c.cx += u * (b.camera.cx - c.cx);
    c.cy += u * (b.camera.cy - c.cy);
    const glm::vec3 eye = glm::mix(a.camera.position(), b.camera.position(), u);
    out.push_back({t, camera_at(eye, glm::slerp(a.camera.orientation(), b.camera.orientation(), u), c)});
  }
  return out;
}

Trace make_orbit(const Bounds& bounds, float radius, float height_offset, float degrees, const GeneratorParams& p) {
  glm::vec3 a, b;
  plane_basis(p.up, &a, &b);
  const glm::vec3 c = bounds.center(), up = glm::normalize(p.up);
  return generate(p, [&](float s) {
    const float th = glm::radians(degrees) * s;
    const glm::vec3 eye = c + radius * (std::cos(th) * a + std::sin(th) * b) + height_offset * up;
    return std::pair{eye, look_rotation(eye, c, up)};
  });
}

Trace make_pan(const glm::vec3& eye, const glm::vec3& look_at, float degrees, const GeneratorParams& p) {
  const glm::vec3 up = glm::normalize(p.up);
  const glm::quat start = look_rotation(eye, look_at, up);
  return generate(p, [&](float s) {
    return std::pair{eye, glm::normalize(glm::angleAxis(glm::radians(degrees) * s, up) * start)};
  });
}

Trace make_zoom(const Bounds& bounds, const glm::vec3& direction, float from, float to, const GeneratorParams& p) {
  const glm::vec3 c = bounds.center(), d = glm::normalize(direction);
  return generate(p, [&](float s) {
    const glm::vec3 eye = c + (from + (to - from) * s) * d;
    return std::pair{eye, look_rotation(eye, c, p.up)};
  });
}

Trace make_flyover(const glm::vec3& start, const glm::vec3& end, float pitch_deg, const GeneratorParams& p) {
  const glm::vec3 up = glm::normalize(p.up);
  glm::vec3 fwd = end - start;
  fwd -= glm::dot(fwd, up) * up;
  if (glm::length(fwd) < 1e-6f) throw std::invalid_argument("fly-over needs horizontal motion");
  fwd = glm::normalize(fwd);
  const float pitch = glm::radians(pitch_deg);
  const glm::vec3 look = std::cos(pitch) * fwd - std::sin(pitch) * up;
  return generate(p, [&](float s) {
    const glm::vec3 eye = start + s * (end - start);
    return std::pair{eye, look_rotation(eye, eye + look, up)};
  });
}

void write_trace(const Trace& trace, const std::string& path) {
  std::ofstream out(path, std::ios::trunc);
  if (!out) throw std::runtime_error(path + ": cannot open for writing");
  out << "catgs-trace 1\n# time_s px py pz qw qx qy qz fx fy cx cy width height\n";
  char line[512];
  for (const auto& tc : trace) {
    const glm::vec3 p = tc.camera.position();
    const glm::quat q = tc.camera.orientation();
    const Camera& c = tc.camera;
    std::snprintf(line, sizeof line, "%.9g %.9g %.9g %.9g %.9g %.9g %.9g %.9g %.9g %.9g %.9g %.9g %d %d\n", tc.time_s,
                  p.x, p.y, p.z, q.w, q.x, q.y, q.z, c.fx, c.fy, c.cx, c.cy, c.width, c.height);
    out << line;
  }
  if (!out) throw std::runtime_error(path + ": write failed");
}

Trace read_trace(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open file");
  std::string line;
  int line_no = 0;
  Trace trace;
  bool have_magic = false;
  while (std::getline(in, line)) {
    ++line_no;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    auto fail = [&](const std::string& why) {
      throw std::runtime_error(path + ":" + std::to_string(line_no) + ": " + why);
    };
    std::istringstream ls(line);
    if (!have_magic) {
      std::string magic;
      int version = 0;
      ls >> magic >> version;
      if (magic != "catgs-trace" || version != 1) fail("expected 'catgs-trace 1'");
      have_magic = true;
      continue;
    }
    double t;
    float v[11];
    int w, h;
    ls >> t;
    for (float& x : v) ls >> x;
    ls >> w >> h;
    std::string extra;
    if (!ls || (ls >> extra)) fail("expected 14 fields");
    Camera c;
    c.fx = v[7];
    c.fy = v[8];
    c.cx = v[9];
    c.cy = v[10];
    c.width = w;
    c.height = h;
    if (!std::isfinite(t) || w < 1 || h < 1 || !(c.fx > 0) || !(c.fy > 0)) fail("bad time, size or intrinsics");
    if (!trace.empty() && t < trace.back().time_s) fail("time goes backwards");
    try {
      trace.push_back(
          {t,
           camera_at({v[0], v[1], v[2]},
                     Camera::from_pose({v[0], v[1], v[2]}, {v[3], v[4], v[5], v[6]}, 60.0f, w, h).orientation(), c)});
    } catch (const std::invalid_argument& e) {
      fail(e.what());
    }
  }
  if (!have_magic) throw std::runtime_error(path + ": empty trace file (no 'catgs-trace 1' line)");
  return trace;
}

}  // namespace catgs
