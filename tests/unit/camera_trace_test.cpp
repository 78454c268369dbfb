// Camera maths, INRIA cameras.json, interpolation, generators and the trace file.
#include <cmath>
#include <fstream>

#include <gtest/gtest.h>

#include "camera/camera.h"
#include "camera/trace.h"
#include "test_data.h"

namespace catgs {
namespace {

// Pixel-unit projection of a world point (the forward model's convention).
glm::vec2 project(const Camera& c, glm::vec3 p) {
  const glm::vec3 q = c.R * p + c.t;
  return {c.fx * q.x / q.z + c.cx - 0.5f, c.fy * q.y / q.z + c.cy - 0.5f};
}

TEST(Camera, FromPoseRoundTrips) {
  const glm::quat q = glm::normalize(glm::quat(0.9f, 0.1f, -0.3f, 0.2f));
  const Camera c = Camera::from_pose({1.0f, -2.0f, 3.0f}, q, 50.0f, 640, 480);
  EXPECT_NEAR(glm::distance(c.position(), glm::vec3(1, -2, 3)), 0.0f, 1e-5f);
  EXPECT_NEAR(std::fabs(glm::dot(c.orientation(), q)), 1.0f, 1e-5f);
  EXPECT_NEAR(c.vertical_fov_deg(), 50.0f, 1e-3f);
  EXPECT_FLOAT_EQ(c.cx, 320.0f);
  EXPECT_FLOAT_EQ(c.fx, c.fy);
  // A point straight ahead lands on the centre pixel; +x camera axis goes right, +y down.
  const glm::mat3 c2w = glm::mat3_cast(q);
  const glm::vec2 centre = project(c, c.position() + 5.0f * c2w[2]);
  EXPECT_NEAR(centre.x, 319.5f, 1e-3f);
  EXPECT_NEAR(centre.y, 239.5f, 1e-3f);
  EXPECT_GT(project(c, c.position() + 5.0f * c2w[2] + 0.5f * c2w[0]).x, 319.5f);
  EXPECT_GT(project(c, c.position() + 5.0f * c2w[2] + 0.5f * c2w[1]).y, 239.5f);
}

TEST(Camera, FromPoseRejectsBadInput) {
  EXPECT_THROW(Camera::from_pose({NAN, 0, 0}, glm::quat(1, 0, 0, 0), 60, 64, 64), std::invalid_argument);
  EXPECT_THROW(Camera::from_pose({0, 0, 0}, glm::quat(0, 0, 0, 0), 60, 64, 64), std::invalid_argument);
  EXPECT_THROW(Camera::from_pose({0, 0, 0}, glm::quat(1, 0, 0, 0), 180, 64, 64), std::invalid_argument);
  EXPECT_THROW(Camera::from_pose({0, 0, 0}, glm::quat(1, 0, 0, 0), 60, 0, 64), std::invalid_argument);
}

// A headset eye's asymmetric frustum (issue 94; loadgen's HeadsetOptics' left eye): each
// edge's direction, built from its angle alone, lands on that edge of the image.
TEST(Camera, FromFrustumPutsEachEdgeOnItsAngle) {
  const float left = -0.942f, right = 0.698f, up = 0.768f, down = -0.873f;
  const glm::quat q = glm::normalize(glm::quat(0.9f, 0.1f, -0.3f, 0.2f));
  const glm::vec3 at(1.0f, -2.0f, 3.0f);
  const Camera c = Camera::from_frustum(at, q, left, right, up, down, 1280, 1344);
  const glm::mat3 c2w = glm::mat3_cast(q);
  // Camera axes: x right, y down, z forward; "up" is -y.
  auto along = [&](float tx, float ty) { return project(c, at + 4.0f * (c2w * glm::vec3(tx, ty, 1.0f))); };
  EXPECT_NEAR(along(std::tan(left), 0.0f).x + 0.5f, 0.0f, 1e-2f);
  EXPECT_NEAR(along(std::tan(right), 0.0f).x + 0.5f, 1280.0f, 1e-2f);
  EXPECT_NEAR(along(0.0f, -std::tan(up)).y + 0.5f, 0.0f, 1e-2f);
  EXPECT_NEAR(along(0.0f, -std::tan(down)).y + 0.5f, 1344.0f, 1e-2f);
  EXPECT_NEAR(glm::distance(c.position(), at), 0.0f, 1e-5f);
  // A symmetric frustum is from_pose's camera.
  const float half = glm::radians(30.0f);
  const Camera s = Camera::from_frustum(at, q, -half, half, half, -half, 640, 640);
  const Camera p = Camera::from_pose(at, q, 60.0f, 640, 640);
  EXPECT_NEAR(s.fx, p.fx, 1e-3f);
  EXPECT_NEAR(s.fy, p.fy, 1e-3f);
  EXPECT_NEAR(s.cx, p.cx, 1e-3f);
  EXPECT_NEAR(s.cy, p.cy, 1e-3f);
  EXPECT_THROW(Camera::from_frustum(at, q, 0.5f, -0.5f, 0.5f, -0.5f, 64, 64), std::invalid_argument);
  EXPECT_THROW(Camera::from_frustum(at, q, -1.6f, 0.5f, 0.5f, -0.5f, 64, 64), std::invalid_argument);
}

TEST(Camera, RescaleKeepsTheView) {
  const Camera c = Camera::from_pose({0, 0, 0}, glm::quat(1, 0, 0, 0), 60.0f, 1000, 500);
  const Camera s = c.rescaled(500, 250);
  const glm::vec3 p(0.3f, -0.2f, 4.0f);
  // Same point, same place in continuous image coordinates (pixel units + 0.5).
  EXPECT_NEAR((project(s, p).x + 0.5f) * 2.0f, project(c, p).x + 0.5f, 1e-3f);
  EXPECT_NEAR((project(s, p).y + 0.5f) * 2.0f, project(c, p).y + 0.5f, 1e-3f);
}

TEST(InriaCameras, LoadsFlowersTrainingCameras) {
  CATGS_REQUIRE_DATA(path, "traces/flowers_sh3.cameras.json");
  const auto full = load_inria_cameras(path);
  ASSERT_EQ(full.size(), 173u);
  EXPECT_EQ(full[0].width, 5025);
  EXPECT_EQ(full[0].height, 3312);
  EXPECT_FLOAT_EQ(full[0].cx, 5025.0f / 2.0f);
  const auto small = load_inria_cameras(path, 1280, 844);
  EXPECT_EQ(small[5].width, 1280);
  EXPECT_NEAR(small[5].fx, full[5].fx * 1280.0f / 5025.0f, 1e-3f);
  EXPECT_NEAR(glm::distance(small[5].position(), full[5].position()), 0.0f, 1e-5f);
}

TEST(InriaCameras, MalformedFilesNameTheProblem) {
  const std::string dir = test::temp_dir();
  auto expect_error = [](const std::string& p, const std::string& what) {
    try {
      load_inria_cameras(p);
      ADD_FAILURE() << "expected an error for " << p;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  std::ofstream(dir + "/broken.json") << "[{\"id\": 0,";
  expect_error(dir + "/broken.json", "malformed JSON");
  std::ofstream(dir + "/nofx.json")
      << R"([{"id":0,"width":4,"height":4,"position":[0,0,0],"rotation":[[1,0,0],[0,1,0],[0,0,1]],"fy":2}])";
  expect_error(dir + "/nofx.json", "camera entry 0");
  expect_error(dir + "/missing.json", "cannot open");
}

TEST(Interpolation, PassesThroughKeysAndIsSmooth) {
  CATGS_REQUIRE_DATA(path, "traces/tandt_train.cameras.json");
  const auto keys = load_inria_cameras(path, 640, 360);
  const Trace t = interpolate_views(keys, 120.0, 0.5);
  ASSERT_EQ(t.size(), (keys.size() - 1) * 60 + 1);
  EXPECT_DOUBLE_EQ(t[60].time_s, 0.5);
  float max_key_step = 0.0f;
  for (std::size_t k = 0; k < keys.size(); ++k) {
    EXPECT_NEAR(glm::distance(t[k * 60].camera.position(), keys[k].position()), 0.0f, 1e-4f) << k;
    EXPECT_NEAR(std::fabs(glm::dot(t[k * 60].camera.orientation(), keys[k].orientation())), 1.0f, 1e-4f);
    if (k > 0) max_key_step = std::max(max_key_step, glm::distance(keys[k].position(), keys[k - 1].position()));
  }
  // No jumps: a 120 Hz step never exceeds a few times the largest key gap spread over its samples.
  for (std::size_t i = 1; i < t.size(); ++i) {
    ASSERT_LT(glm::distance(t[i].camera.position(), t[i - 1].camera.position()), 3.0f * max_key_step / 60.0f) << i;
    ASSERT_GT(std::fabs(glm::dot(t[i].camera.orientation(), t[i - 1].camera.orientation())), 0.99f) << i;
  }
}

TEST(Interpolation, RejectsTooFewKeys) {
  EXPECT_THROW(interpolate_views({Camera{}}, 120.0, 1.0), std::invalid_argument);
}

TEST(Generators, OrbitCirclesAndLooksAtTheCentre) {
  const Bounds b{{-1, -1, -1}, {1, 3, 1}};
  GeneratorParams p;
  p.width = 320;
  p.height = 240;
  const Trace t = make_orbit(b, 5.0f, 1.0f, 360.0f, p);
  ASSERT_EQ(t.size(), 601u);
  for (const auto& tc : t) {
    EXPECT_NEAR(glm::distance(tc.camera.position(), b.center()), std::sqrt(26.0f), 1e-3f);
    const glm::vec2 c = project(tc.camera, b.center());
    EXPECT_NEAR(c.x, 159.5f, 1e-2f);
    EXPECT_NEAR(c.y, 119.5f, 1e-2f);
  }
  EXPECT_NEAR(glm::distance(t.front().camera.position(), t.back().camera.position()), 0.0f, 1e-3f);
}

TEST(Generators, FlyoverPitchesDownAndZoomApproaches) {
  GeneratorParams p;
  p.up = {0, 1, 0};
  const Trace f = make_flyover({0, 2, 0}, {10, 2, 0}, 30.0f, p);
  const glm::vec3 fwd = glm::mat3_cast(f[10].camera.orientation())[2];
  EXPECT_NEAR(glm::degrees(std::asin(-fwd.y)), 30.0f, 1e-2f);
  const Trace z = make_zoom({{-1, -1, -1}, {1, 1, 1}}, {0, 0, 1}, 10.0f, 2.0f, p);
  EXPECT_NEAR(glm::length(z.front().camera.position()), 10.0f, 1e-4f);
  EXPECT_NEAR(glm::length(z.back().camera.position()), 2.0f, 1e-4f);
  const Trace pan = make_pan({0, 0, 0}, {0, 0, 1}, 90.0f, p);
  EXPECT_NEAR(glm::dot(glm::mat3_cast(pan.back().camera.orientation())[2], glm::vec3(1, 0, 0)), 1.0f, 1e-4f);
}

TEST(TraceFile, WriteThenReadRoundTrips) {
  GeneratorParams p;
  p.duration_s = 1.0;
  const Trace a = make_orbit({{-1, -1, -1}, {1, 1, 1}}, 4.0f, 0.5f, 90.0f, p);
  const std::string path = test::temp_dir() + "/orbit.trace";
  write_trace(a, path);
  const Trace b = read_trace(path);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_NEAR(a[i].time_s, b[i].time_s, 1e-9);
    EXPECT_NEAR(glm::distance(a[i].camera.position(), b[i].camera.position()), 0.0f, 1e-5f);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[i].camera.R[c][r], b[i].camera.R[c][r], 1e-5f);
    EXPECT_FLOAT_EQ(a[i].camera.fx, b[i].camera.fx);
    EXPECT_EQ(a[i].camera.width, b[i].camera.width);
  }
}

TEST(TraceFile, MalformedLinesNameFileAndLine) {
  const std::string dir = test::temp_dir();
  auto expect_error = [](const std::string& p, const std::string& what) {
    try {
      read_trace(p);
      ADD_FAILURE() << "expected an error for " << p;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  std::ofstream(dir + "/magic.trace") << "hello 1\n";
  expect_error(dir + "/magic.trace", "magic.trace:1: expected 'catgs-trace 1'");
  std::ofstream(dir + "/short.trace") << "catgs-trace 1\n0 0 0 0 1 0 0 0 100 100 50\n";
  expect_error(dir + "/short.trace", "short.trace:2: expected 14 fields");
  std::ofstream(dir + "/back.trace") << "catgs-trace 1\n1 0 0 0 1 0 0 0 100 100 50 50 100 100\n"
                                        "0 0 0 0 1 0 0 0 100 100 50 50 100 100\n";
  expect_error(dir + "/back.trace", "back.trace:3: time goes backwards");
  std::ofstream(dir + "/nan.trace") << "catgs-trace 1\n0 nan 0 0 1 0 0 0 100 100 50 50 100 100\n";
  expect_error(dir + "/nan.trace", "nan.trace:2");
}

}  // namespace
}  // namespace catgs
