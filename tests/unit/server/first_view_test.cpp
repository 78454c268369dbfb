// The first view (server/process/first_view.h): the least-squares meeting point of optical axes,
// the frame from training cameras, the dense content of real scenes, cameras.json discovery,
// and, on the real scenes, that the first view and views orbited from it show what the training
// cameras photographed.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include "camera/trace.h"
#include "common/image_io.h"
#include "cpu/cpu_renderer.h"
#include "scene/scene_bounds.h"
#include "process/first_view.h"
#include "test_data.h"

namespace {

using namespace catgs;
using namespace catgs::server;
namespace fs = std::filesystem;

constexpr int kW = 160, kH = 90;  // small renders: the content, not the detail, is compared

// Camera-to-world rotation looking along `forward` with world `up` (OpenCV axes).
glm::quat look_along(glm::vec3 forward, glm::vec3 up) {
  const glm::vec3 z = glm::normalize(forward);
  const glm::vec3 x = glm::normalize(glm::cross(-up, z));
  return glm::quat_cast(glm::mat3(x, glm::cross(z, x), z));
}

Camera camera_at(glm::vec3 eye, glm::vec3 target, glm::vec3 up, float fov_deg = 50.0f) {
  return Camera::from_pose(eye, look_along(target - eye, up), fov_deg, 400, 300);
}

// A ring of cameras around `target` at various heights, all looking at it.
std::vector<Camera> ring(glm::vec3 target, glm::vec3 up, float radius, int n) {
  const glm::vec3 a = glm::normalize(glm::cross(up, glm::vec3(0.3f, 0.1f, 1.0f)));
  const glm::vec3 b = glm::cross(up, a);
  std::vector<Camera> cams;
  for (int k = 0; k < n; ++k) {
    const float phi = 6.2831853f * static_cast<float>(k) / static_cast<float>(n);
    const float height = 0.3f * radius * std::sin(3.0f * phi);
    cams.push_back(camera_at(target + radius * (std::cos(phi) * a + std::sin(phi) * b) + height * up, target, up));
  }
  return cams;
}

float degrees_between(glm::vec3 a, glm::vec3 b) {
  return glm::degrees(std::acos(std::clamp(glm::dot(glm::normalize(a), glm::normalize(b)), -1.0f, 1.0f)));
}

TEST(FirstView, AxesMeetingAtAKnownPoint) {
  const glm::vec3 target(1.5f, -2.0f, 7.0f);
  std::vector<glm::vec3> origins, dirs;
  for (const Camera& c : ring(target, glm::normalize(glm::vec3(0.2f, -1.0f, 0.1f)), 4.0f, 12)) {
    origins.push_back(c.position());
    dirs.push_back(3.0f * (target - c.position()));  // any length
  }
  const auto p = nearest_point_to_lines(origins, dirs);
  ASSERT_TRUE(p);
  EXPECT_LT(glm::distance(*p, target), 1e-4f);
  // Two skew lines: the midpoint of their common perpendicular.
  const auto q = nearest_point_to_lines({{0, 0, 0}, {0, 1, 0}}, {{1, 0, 0}, {0, 0, 1}});
  ASSERT_TRUE(q);
  EXPECT_LT(glm::distance(*q, glm::vec3(0.0f, 0.5f, 0.0f)), 1e-5f);
}

TEST(FirstView, DegenerateAxesHaveNoMeetingPoint) {
  // Parallel axes (a forward-facing capture), one axis, a zero direction, mismatched sizes.
  EXPECT_FALSE(nearest_point_to_lines({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 0, 1}, {0, 0, 1}, {0, 0, 2}}));
  EXPECT_FALSE(nearest_point_to_lines({{0, 0, 0}}, {{0, 0, 1}}));
  EXPECT_FALSE(nearest_point_to_lines({{0, 0, 0}, {1, 0, 0}}, {{0, 0, 1}, {0, 0, 0}}));
  EXPECT_FALSE(nearest_point_to_lines({{0, 0, 0}, {1, 0, 0}}, {{0, 0, 1}}));
}

TEST(FirstView, FrameFromConstructedCameras) {
  const glm::vec3 target(-3.0f, 0.5f, 2.0f);
  const glm::vec3 up = glm::normalize(glm::vec3(0.3f, -1.0f, 0.2f));
  std::vector<Camera> cams = ring(target, up, 5.0f, 9);
  const SceneFrame f = frame_from_cameras(cams, "ring");
  EXPECT_LT(glm::distance(f.orbit_centre, target), 1e-3f);
  EXPECT_LT(degrees_between(f.up, up), 0.5f);
  std::vector<float> reach;
  for (const Camera& c : cams) reach.push_back(glm::distance(c.position(), target));
  std::nth_element(reach.begin(), reach.begin() + 4, reach.end());
  EXPECT_NEAR(f.scene_scale, reach[4], 1e-3f);  // the median
  ASSERT_TRUE(f.training_view);
  EXPECT_NEAR(f.training_view->vertical_fov_deg, 50.0f, 0.01f);
  const CameraPose p = first_view_pose(f, 320, 200);
  EXPECT_LT(degrees_between(p.orientation * glm::vec3(0, 0, 1), target - p.position), 0.1f);
  EXPECT_NE(f.source.find("ring, camera "), std::string::npos) << f.source;

  // Camera 0, first in file order, looks well to the side: the first view is another camera.
  cams[0] = camera_at(cams[0].position(), target + 2.0f * glm::cross(up, target - cams[0].position()), up);
  const SceneFrame g = frame_from_cameras(cams, "ring");
  ASSERT_TRUE(g.training_view);
  EXPECT_GT(glm::distance(g.training_view->position, cams[0].position()), 1.0f);
}

TEST(FirstView, ParallelCamerasLookAhead) {
  // A forward-facing row: the axes never meet; the centre is ahead of the cameras.
  std::vector<Camera> cams;
  for (int k = 0; k < 5; ++k)
    cams.push_back(camera_at({static_cast<float>(k), 0, 0}, {static_cast<float>(k), 0, 10}, {0, -1, 0}));
  const SceneFrame f = frame_from_cameras(cams, "row");
  EXPECT_GT(f.orbit_centre.z, 0.5f);
  EXPECT_NEAR(f.orbit_centre.x, 2.0f, 1e-4f);
  EXPECT_GT(f.scene_scale, 0.0f);
  EXPECT_THROW(frame_from_cameras({}, "none"), std::invalid_argument);
}

// ---- the real scenes ----

Image render(const GaussianModel& model, const CameraPose& view) {
  Image img;
  cpu::CpuRenderer(std::shared_ptr<const GaussianModel>(&model, [](const GaussianModel*) {}), RenderOptions{})
      .render(Camera::from_pose(view.position, view.orientation, view.vertical_fov_deg, kW, kH), img);
  return img;
}

void shot(const Image& img, const std::string& name) {  // CATGS_FIRST_VIEW_SHOTS=DIR keeps the renders
  if (const char* dir = std::getenv("CATGS_FIRST_VIEW_SHOTS")) write_png(img, std::string(dir) + "/" + name + ".png");
}

CameraPose pose_of(const Camera& c) { return {c.position(), c.orientation(), c.vertical_fov_deg()}; }

// `pose` turned by `degrees` about the axis through `centre` along `up` (what the viewer's orbit
// does with Welcome's orbit_centre and up).
CameraPose orbited(const CameraPose& pose, glm::vec3 centre, glm::vec3 up, float degrees) {
  const glm::quat turn = glm::angleAxis(glm::radians(degrees), glm::normalize(up));
  CameraPose p = pose;
  p.position = centre + turn * (pose.position - centre);
  p.orientation = glm::normalize(turn * pose.orientation);
  return p;
}

const Camera& nearest_camera(const std::vector<Camera>& cams, glm::vec3 p) {
  return *std::min_element(cams.begin(), cams.end(), [&](const Camera& a, const Camera& b) {
    return glm::distance(a.position(), p) < glm::distance(b.position(), p);
  });
}

// flowers_sh3 and its training cameras (same world frame). The photographed region is the ball
// the cameras stand in, around the point their axes meet; the scene without it (its Gaussians
// made transparent) is the background.
struct Flowers {
  std::shared_ptr<const GaussianModel> model;
  GaussianModel background;
  std::vector<Camera> cameras;
  glm::vec3 cameras_centre{0.0f};
  float farthest = 0.0f;  // the farthest camera from cameras_centre
};

Flowers flowers(const std::string& scene, const std::string& cams) {
  Flowers f;
  f.model = test::cached_scene(scene);
  f.cameras = load_inria_cameras(cams);
  std::vector<glm::vec3> origins, dirs;
  for (const Camera& c : f.cameras) {
    origins.push_back(c.position());
    dirs.push_back(c.orientation() * glm::vec3(0, 0, 1));
  }
  f.cameras_centre = nearest_point_to_lines(origins, dirs).value();
  for (const Camera& c : f.cameras) f.farthest = std::max(f.farthest, glm::distance(c.position(), f.cameras_centre));
  f.background = *f.model;
  for (std::size_t i = 0; i < f.model->size(); ++i) {
    const glm::vec3 m(f.model->means[3 * i], f.model->means[3 * i + 1], f.model->means[3 * i + 2]);
    if (glm::distance(m, f.cameras_centre) <= f.farthest) f.background.opacity_logits[i] = -kOpacityLogitLimit;
  }
  return f;
}

// The share of a view's pixels that the photographed region forms: pixels whose colour changes
// (by more than 30 of 765 summed over RGB) when the region is taken away. Occlusion counts: a
// subject hidden behind background Gaussians, or too small to see, forms few pixels.
double photographed_share(const Flowers& f, const CameraPose& view, const std::string& name) {
  const Image full = render(*f.model, view), background = render(f.background, view);
  shot(full, name);
  std::size_t formed = 0;
  for (std::size_t k = 0; k < full.rgba8.size(); k += 4) {
    int diff = 0;
    for (int c = 0; c < 3; ++c) diff += std::abs(full.rgba8[k + c] - background.rgba8[k + c]);
    formed += diff > 30 ? 1 : 0;
  }
  return static_cast<double>(formed) / (kW * kH);
}

// photographed_share of `view` and of the training camera nearest to it.
std::pair<double, double> seen_and_seen_by_nearest_camera(const Flowers& f, const CameraPose& view,
                                                          const std::string& name) {
  const Camera& near = nearest_camera(f.cameras, view.position);
  const double seen = photographed_share(f, view, name);
  const double seen_by_camera = photographed_share(f, pose_of(near), name + "_nearest");
  std::cout << "  " << name << ": view " << glm::distance(view.position, f.cameras_centre)
            << " from the cameras' centre; the photographed region forms " << seen << " of it, " << seen_by_camera
            << " of the nearest training camera's (" << glm::distance(near.position(), view.position) << " away)\n";
  return {seen, seen_by_camera};
}

// The first view, and views orbited 30 degrees either way about Welcome's orbit centre and up,
// show the photographed region at least half as much as the nearest training camera does.
// Measured (share of the view / share of the nearest training camera's): from the cameras 0.46 /
// 0.46, 0.47 / 0.32, 0.46 / 0.40; from the content 0.50 / 0.66, 0.53 / 0.61, 0.49 / 0.67; the old
// first view of flowers (robust bounds, 62 units from the cameras' centre) 0 / 0.27.
void expect_shows_what_was_photographed(const Flowers& f, const SceneFrame& frame, const std::string& tag) {
  const CameraPose first = first_view_pose(frame, kW, kH);
  for (float degrees : {0.0f, 30.0f, -30.0f}) {
    const CameraPose view = orbited(first, frame.orbit_centre, frame.up, degrees);
    const std::string name = tag + "_orbit" + std::to_string(static_cast<int>(degrees));
    const auto [seen, seen_by_camera] = seen_and_seen_by_nearest_camera(f, view, name);
    EXPECT_GT(seen, 0.5 * seen_by_camera) << name << ": " << frame.source;
  }
}

TEST(FirstViewRealScenes, FlowersWithItsCameras) {
  CATGS_REQUIRE_DATA(scene, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const Flowers fl = flowers(scene, cams);
  const SceneFrame frame = frame_from_cameras(fl.cameras, cams);
  std::cout << "  " << frame.source << ", scene scale " << frame.scene_scale << "\n";
  EXPECT_LE(glm::distance(first_view_pose(frame, kW, kH).position, frame.orbit_centre), fl.farthest);
  EXPECT_LT(frame.scene_scale, fl.farthest);
  expect_shows_what_was_photographed(fl, frame, "cameras");
}

TEST(FirstViewRealScenes, FlowersFromItsContent) {
  CATGS_REQUIRE_DATA(scene, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const Flowers fl = flowers(scene, cams);
  const SceneFrame frame = frame_from_content(*fl.model);
  const SceneFrame truth = frame_from_cameras(fl.cameras, cams);
  const float out = glm::distance(first_view_pose(frame, kW, kH).position, fl.cameras_centre);
  const float up_error = degrees_between(frame.up, truth.up);
  std::cout << "  " << frame.source << ": first view " << out << " from the cameras' centre (farthest camera "
            << fl.farthest << "), up " << up_error << " degrees from the cameras' mean up\n";
  EXPECT_LT(out, 2.0f * fl.farthest);  // the old first view: 62.5 out, the cameras within 4.3
  EXPECT_LT(up_error, 10.0f);
  expect_shows_what_was_photographed(fl, frame, "content");
}

// The check above can fail: the first view of the code before this module framed the robust
// bounds (2nd..98th percentiles of the means) from -z, raised towards -y, and stood in the
// background, 62.5 units from the cameras' centre (the same pose: a frame without content points
// frames the sphere as that code did).
TEST(FirstViewRealScenes, FlowersBoundsFramingFailsTheCheck) {
  CATGS_REQUIRE_DATA(scene, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const Flowers fl = flowers(scene, cams);
  SceneFrame bounds_frame;  // up -y
  const Bounds rb = robust_bounds(*fl.model, 0.02f);
  bounds_frame.orbit_centre = rb.center();
  bounds_frame.content_radius = 0.5f * glm::length(rb.extent());
  const auto [seen, seen_by_camera] =
      seen_and_seen_by_nearest_camera(fl, first_view_pose(bounds_frame, kW, kH), "bounds_orbit0");
  EXPECT_LT(seen, 0.5 * seen_by_camera);
}

// Scenes without training cameras here: the first view, and views orbited from it, keep the
// content in the picture: most of the robust bounds' Gaussians project into it, and the render
// is lit.
void expect_frames_the_object(const std::string& scene) {
  const auto model = test::cached_scene(scene);
  const SceneFrame frame = frame_from_content(*model);
  std::cout << "  " << frame.source << "\n";
  const Bounds box = robust_bounds(*model, 0.02f);
  for (float degrees : {0.0f, 30.0f, -30.0f}) {
    const CameraPose view = orbited(first_view_pose(frame, kW, kH), frame.orbit_centre, frame.up, degrees);
    const Camera cam = Camera::from_pose(view.position, view.orientation, view.vertical_fov_deg, kW, kH);
    std::size_t inside = 0, in_view = 0;
    for (std::size_t i = 0; i < model->size(); ++i) {
      const glm::vec3 m(model->means[3 * i], model->means[3 * i + 1], model->means[3 * i + 2]);
      if (glm::any(glm::lessThan(m, box.min)) || glm::any(glm::greaterThan(m, box.max))) continue;
      ++inside;
      const glm::vec3 c = cam.R * m + cam.t;
      const float u = cam.fx * c.x / c.z + cam.cx, v = cam.fy * c.y / c.z + cam.cy;
      in_view += c.z > 0.0f && u >= 0.0f && u < kW && v >= 0.0f && v < kH ? 1 : 0;
    }
    const Image img = render(*model, view);
    std::size_t lit = 0;
    for (std::size_t k = 0; k < img.rgba8.size(); k += 4)
      lit += img.rgba8[k] + img.rgba8[k + 1] + img.rgba8[k + 2] > 30;
    const double in_view_share = static_cast<double>(in_view) / static_cast<double>(inside);
    const double lit_share = static_cast<double>(lit) / (kW * kH);
    std::cout << "  orbit " << degrees << " deg: " << in_view_share << " of the content in view, " << lit_share
              << " of the picture lit\n";
    EXPECT_GT(in_view_share, 0.9) << "orbit " << degrees;
    EXPECT_GT(lit_share, 0.05) << "orbit " << degrees;  // as the integration test: not (nearly) empty
  }
}

TEST(FirstViewRealScenes, TumblewoodFromItsContent) {
  CATGS_REQUIRE_DATA(scene, "scenes/tumblewood_sh2.ply");
  expect_frames_the_object(scene);
}

TEST(FirstViewRealScenes, BikerFromItsContent) {
  CATGS_REQUIRE_DATA(scene, "scenes/biker.compressed.ply");
  expect_frames_the_object(scene);
}

// ---- objects framed whole (issue 38, item 5) ----

std::string copy_cameras(const std::string& from, const fs::path& to) {
  fs::create_directories(to.parent_path());
  fs::copy_file(from, to, fs::copy_options::overwrite_existing);
  return to.string();
}

// Where the object is in a render on the black background: the bounding box of the pixels whose
// RGB sum exceeds `threshold` (of 765), and how many there are.
struct ObjectPixels {
  int left = 0, top = 0, right = -1, bottom = -1;  // inclusive; right < left: none
  std::size_t count = 0;
};

ObjectPixels object_pixels(const Image& img, int threshold) {
  ObjectPixels o{img.width, img.height, -1, -1, 0};
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const std::uint8_t* px = &img.rgba8[4 * (static_cast<std::size_t>(y) * img.width + x)];
      if (px[0] + px[1] + px[2] <= threshold) continue;
      ++o.count;
      o.left = std::min(o.left, x);
      o.right = std::max(o.right, x);
      o.top = std::min(o.top, y);
      o.bottom = std::max(o.bottom, y);
    }
  return o;
}

// The first frame of an object capture without training cameras, rendered by the CPU core:
// background on all four sides of the object (no object pixel in a border 5% of the picture
// wide on any side: a guitar whose headstock sat 6 px from a 180 px picture's top failed it), the object centred (the free space left and right, and above and below,
// differ by at most 10% of the picture) and large (its box spans at least 60% of the picture's
// width or height). Landscape and portrait viewports alike. CATGS_FIRST_VIEW_SHOTS keeps the
// renders. Object pixels: RGB sum above 30 of 765 (the black background is 0; the faint halo of
// low-opacity Gaussians around the object stays below it).
void expect_framed_whole_and_centred(const std::string& scene, const std::string& tag) {
  const auto model = test::cached_scene(scene);
  const SceneFrame frame = frame_from_content(*model);
  std::cout << "  " << frame.source << "\n";
  for (const auto& [w, h] : {std::pair{320, 180}, std::pair{180, 320}}) {
    const CameraPose view = first_view_pose(frame, w, h);
    Image img;
    cpu::CpuRenderer(model, RenderOptions{})
        .render(Camera::from_pose(view.position, view.orientation, view.vertical_fov_deg, w, h), img);
    shot(img, tag + "_first_" + std::to_string(w) + "x" + std::to_string(h));
    const ObjectPixels o = object_pixels(img, 30);
    ASSERT_GT(o.count, 0u) << tag << " " << w << "x" << h << ": nothing on screen";
    const int free_left = o.left, free_right = w - 1 - o.right, free_top = o.top, free_bottom = h - 1 - o.bottom;
    std::cout << "  " << w << "x" << h << ": object box x " << o.left << ".." << o.right << ", y " << o.top << ".."
              << o.bottom << "; free left " << free_left << ", right " << free_right << ", top " << free_top
              << ", bottom " << free_bottom << " px\n";
    const int border_x = std::max(1, w / 20), border_y = std::max(1, h / 20);
    EXPECT_GE(free_left, border_x) << tag << " " << w << "x" << h << ": the object touches the left edge";
    EXPECT_GE(free_right, border_x) << tag << " " << w << "x" << h << ": the object touches the right edge";
    EXPECT_GE(free_top, border_y) << tag << " " << w << "x" << h << ": the object's top is cut off";
    EXPECT_GE(free_bottom, border_y) << tag << " " << w << "x" << h << ": the object's bottom is cut off";
    EXPECT_LE(std::abs(free_left - free_right), w / 10) << tag << " " << w << "x" << h << ": not centred across";
    EXPECT_LE(std::abs(free_top - free_bottom), h / 10) << tag << " " << w << "x" << h << ": not centred up-down";
    EXPECT_TRUE(o.right - o.left + 1 >= 0.6 * w || o.bottom - o.top + 1 >= 0.6 * h)
        << tag << " " << w << "x" << h << ": the object is framed too small";
  }
}

TEST(FirstViewRealScenes, BikerFramedWholeAndCentred) {
  expect_framed_whole_and_centred(test::bundled_scene(), "biker");
}

TEST(FirstViewRealScenes, GuitarFramedWholeAndCentred) {
  CATGS_REQUIRE_DATA(scene, "scenes/guitar.compressed.ply");
  expect_framed_whole_and_centred(scene, "guitar");
}

// A scene with training cameras still opens on one of them, unchanged (the content box plays no
// part): flowers with its cameras.json found beside it.
TEST(FirstViewRealScenes, TrainingCamerasStillGiveTheFirstView) {
  CATGS_REQUIRE_DATA(scene, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const fs::path dir = test::temp_dir();
  copy_cameras(cams, dir / "flowers_sh3.cameras.json");
  std::ostringstream log;
  const SceneFrame f = choose_scene_frame(*test::cached_scene(scene), (dir / "flowers_sh3.ply").string(), "", log);
  const CameraPose first = first_view_pose(f, 320, 180);
  const std::vector<Camera> cameras = load_inria_cameras(cams);
  const bool is_a_camera = std::any_of(cameras.begin(), cameras.end(), [&](const Camera& c) {
    return glm::distance(c.position(), first.position) < 1e-5f &&
           std::fabs(glm::dot(c.orientation(), first.orientation)) > 1.0f - 1e-6f;
  });
  EXPECT_TRUE(is_a_camera) << log.str();
}

// ---- up: the estimate against independent references ----

// The normal of the ground of a capture (grass, a lawn, a floor), signed towards -y: the plane
// that holds the most of the Gaussian means near the scene's middle (the nearest half of them to
// the per-axis median point: an unbounded capture's background is far from any plane) within 2%
// of that half's radius. RANSAC over planes through 3 of those means picked at random (fixed seed;
// 500 tries, scored on at most 20,000 of them, evenly picked), then twice refined by least squares
// (the smallest principal axis of the plane's inliers). A different estimator from content_up
// (the smallest axis of all the means in a ball around the density mode), so they disagree where
// content_up is fooled by what stands on the ground. `inlier_share`: the share of the middle
// half's means within the tolerance of the final plane.
glm::vec3 ground_normal(const GaussianModel& m, double* inlier_share) {
  auto at = [&](std::size_t i) { return glm::dvec3(m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]); };
  glm::dvec3 median;
  for (int a = 0; a < 3; ++a) {
    std::vector<double> v(m.size());
    for (std::size_t i = 0; i < m.size(); ++i) v[i] = m.means[3 * i + a];
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    median[a] = v[v.size() / 2];
  }
  std::vector<double> dist(m.size());
  for (std::size_t i = 0; i < m.size(); ++i) dist[i] = glm::distance(at(i), median);
  std::vector<double> sorted = dist;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
  const double radius = sorted[sorted.size() / 2], tolerance = 0.02 * radius;
  std::vector<glm::dvec3> middle;
  for (std::size_t i = 0; i < m.size(); ++i)
    if (dist[i] <= radius) middle.push_back(at(i));
  std::vector<glm::dvec3> sample;
  const std::size_t stride = std::max<std::size_t>(1, middle.size() / 20000);
  for (std::size_t i = 0; i < middle.size(); i += stride) sample.push_back(middle[i]);
  std::mt19937 rng(18);
  std::uniform_int_distribution<std::size_t> pick(0, sample.size() - 1);
  glm::dvec3 normal(0.0, -1.0, 0.0);
  double offset = 0.0;
  std::size_t best = 0;
  for (int t = 0; t < 500; ++t) {
    const glm::dvec3 a = sample[pick(rng)], b = sample[pick(rng)], c = sample[pick(rng)];
    const glm::dvec3 n = glm::cross(b - a, c - a);
    if (glm::length(n) < 1e-12) continue;
    const glm::dvec3 u = glm::normalize(n);
    std::size_t count = 0;
    for (const glm::dvec3& p : sample) count += std::fabs(glm::dot(u, p - a)) <= tolerance ? 1 : 0;
    if (count > best) {
      best = count;
      normal = u;
      offset = glm::dot(u, a);
    }
  }
  std::size_t inliers = 0;
  for (int refine = 0; refine < 2; ++refine) {
    glm::dvec3 mean(0.0);
    inliers = 0;
    for (const glm::dvec3& p : middle)
      if (std::fabs(glm::dot(normal, p) - offset) <= tolerance) {
        mean += p;
        ++inliers;
      }
    mean /= static_cast<double>(inliers);
    glm::dmat3 cov(0.0);
    for (const glm::dvec3& p : middle)
      if (std::fabs(glm::dot(normal, p) - offset) <= tolerance) cov += glm::outerProduct(p - mean, p - mean);
    // The smallest axis: power iteration on trace(cov) I - cov, started at the current normal.
    const double trace = cov[0][0] + cov[1][1] + cov[2][2];
    const glm::dmat3 flipped = trace * glm::dmat3(1.0) - cov;
    for (int k = 0; k < 500; ++k) normal = glm::normalize(flipped * normal);
    offset = glm::dot(normal, mean);
  }
  inliers = 0;
  for (const glm::dvec3& p : middle) inliers += std::fabs(glm::dot(normal, p) - offset) <= tolerance ? 1 : 0;
  *inlier_share = static_cast<double>(inliers) / static_cast<double>(middle.size());
  return glm::vec3(normal.y > 0.0 ? -normal : normal);
}

// The up estimated from the content (tumblewood has no cameras here) is level: within 3 degrees of
// the normal of its ground, the grass the sign stands in (40% of the middle half's means lie on
// it; CATGS_FIRST_VIEW_SHOTS keeps the first view, the grass level in it). Measured: the estimate
// 1.4 degrees from the ground's normal; -y is 2.4 from it, so this capture's frame is nearly
// level already (the roll of about 20 degrees that issue 18 reports does not reproduce on this
// file: an orbit about -y would roll its horizon by at most 2.4 degrees).
TEST(FirstViewRealScenes, TumblewoodUpIsLevel) {
  CATGS_REQUIRE_DATA(scene, "scenes/tumblewood_sh2.ply");
  const auto model = test::cached_scene(scene);
  double share = 0.0;
  const glm::vec3 ground = ground_normal(*model, &share);
  const SceneFrame frame = frame_from_content(*model);
  std::cout << "  ground normal (" << ground.x << ", " << ground.y << ", " << ground.z << "), " << share
            << " of the means on it; estimated up " << degrees_between(frame.up, ground) << " degrees from it, -y "
            << degrees_between(glm::vec3(0, -1, 0), ground) << "; " << frame.source << "\n";
  EXPECT_GT(share, 0.25);  // the plane is a ground, not a few splats that happen to line up
  EXPECT_NE(frame.source.find("up from its flattest axis"), std::string::npos) << frame.source;
  EXPECT_LT(degrees_between(frame.up, ground), 3.0f);
  shot(render(*model, first_view_pose(frame, kW, kH)), "tumblewood_first");
}

// A model of more than kJudgedGaussians content Gaussians is judged by an even sample of them
// (issue 46: the whole-scene passes were most of a large city's load). Three copies of tumblewood
// side by side (1.6 M Gaussians, every 2nd judged): the sampled frame against the frame judged
// by every Gaussian, the independent full computation. It can fail: a sample taken from one end
// of the arrays (the first million) would see two copies and put the centre a copy away.
TEST(FirstViewRealScenes, LargeModelJudgedBySampleAsByEveryGaussian) {
  CATGS_REQUIRE_DATA(scene, "scenes/tumblewood_sh2.ply");
  const auto one = test::cached_scene(scene);
  const Bounds b = one->bounds();
  const float step = 1.2f * glm::length(b.extent());
  GaussianModel city;
  city.sh_degree = one->sh_degree;
  for (const glm::vec3 offset : {glm::vec3(0.0f), glm::vec3(step, 0.0f, 0.0f), glm::vec3(0.0f, 0.0f, step)}) {
    for (std::size_t i = 0; i < one->size(); ++i)
      for (int a = 0; a < 3; ++a) city.means.push_back(one->means[3 * i + a] + offset[a]);
    city.opacity_logits.insert(city.opacity_logits.end(), one->opacity_logits.begin(), one->opacity_logits.end());
  }
  ASSERT_GT(city.opacity_logits.size(), kJudgedGaussians);
  const SceneFrame sampled = frame_from_content(city);
  const SceneFrame whole = frame_from_content(city, city.opacity_logits.size());
  std::cout << "  sampled: " << sampled.source << "\n  whole:   " << whole.source << "\n  centre "
            << glm::distance(sampled.orbit_centre, whole.orbit_centre) << " apart (radius " << whole.content_radius
            << "), up " << degrees_between(sampled.up, whole.up) << " degrees, scene scale " << sampled.scene_scale
            << " / " << whole.scene_scale << "\n";
  EXPECT_NE(sampled.source.find("judged by 1 in 2 of the Gaussians"), std::string::npos) << sampled.source;
  EXPECT_EQ(whole.source.find("judged by"), std::string::npos) << whole.source;
  EXPECT_EQ(sampled.framed_share, whole.framed_share);  // the same object-or-scene decision
  EXPECT_LT(glm::distance(sampled.orbit_centre, whole.orbit_centre), 0.02f * whole.content_radius);
  EXPECT_NEAR(sampled.content_radius, whole.content_radius, 0.02f * whole.content_radius);
  EXPECT_LT(degrees_between(sampled.up, whole.up), 1.0f);
  EXPECT_NEAR(sampled.scene_scale, whole.scene_scale, 0.03f * whole.scene_scale);
}

// Every real scene with training cameras (flowers only, here): the up estimated from the content is
// within 3 degrees of the cameras' mean up (measured 1.9; -y is 18.1 from it). The ground-plane
// reference agrees with the cameras too (measured: its normal 1.5 degrees from their mean up),
// which is what makes it a fair reference where there are no cameras.
TEST(FirstViewRealScenes, FlowersUpMatchesItsCameras) {
  CATGS_REQUIRE_DATA(scene, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const auto model = test::cached_scene(scene);
  const glm::vec3 cameras_up = frame_from_cameras(load_inria_cameras(cams), cams).up;
  const SceneFrame frame = frame_from_content(*model);
  double share = 0.0;
  const glm::vec3 ground = ground_normal(*model, &share);
  std::cout << "  cameras' mean up (" << cameras_up.x << ", " << cameras_up.y << ", " << cameras_up.z
            << "); estimated up " << degrees_between(frame.up, cameras_up) << " degrees from it, -y "
            << degrees_between(glm::vec3(0, -1, 0), cameras_up) << ", the ground's normal "
            << degrees_between(ground, cameras_up) << " (" << share << " of the means on it)\n";
  EXPECT_LT(degrees_between(frame.up, cameras_up), 3.0f);
  EXPECT_LT(degrees_between(ground, cameras_up), 3.0f);
}

// ---- cameras.json discovery ----

TEST(FirstViewDiscovery, FindsCamerasBesideTheSceneAndInTheInriaLayout) {
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const fs::path dir = test::temp_dir();
  EXPECT_EQ(find_cameras_file((dir / "a.ply").string()), "");
  copy_cameras(cams, dir / "a.cameras.json");
  EXPECT_EQ(find_cameras_file((dir / "a.ply").string()), (dir / "a.cameras.json").string());
  const fs::path model = dir / "model";
  const std::string ply = (model / "point_cloud" / "iteration_30000" / "point_cloud.ply").string();
  EXPECT_EQ(find_cameras_file(ply), "");
  copy_cameras(cams, model / "cameras.json");
  EXPECT_EQ(find_cameras_file(ply), (model / "cameras.json").string());
}

TEST(FirstViewDiscovery, DiscoveredCamerasGiveTheFirstView) {
  CATGS_REQUIRE_DATA(scene, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const fs::path dir = test::temp_dir();
  const std::string ply = (dir / "flowers_sh3.ply").string();
  copy_cameras(cams, dir / "flowers_sh3.cameras.json");
  std::ostringstream log;
  const SceneFrame f = choose_scene_frame(*test::cached_scene(scene), ply, "", log);
  ASSERT_TRUE(f.training_view);
  EXPECT_NE(log.str().find("first view: cameras " + (dir / "flowers_sh3.cameras.json").string()), std::string::npos)
      << log.str();
}

TEST(FirstViewDiscovery, MalformedCamerasFile) {
  const auto model = test::cached_scene(test::bundled_scene());
  const fs::path dir = test::temp_dir();
  const std::string bad = (dir / "biker.cameras.json").string();
  std::ofstream(bad) << R"([{"id": 0, "width": 640, "height": 480, "fx": 500, "fy": 500, "position": [0, 0]}])";
  // Named on the command line: an error naming the file and the entry.
  try {
    choose_scene_frame(*model, (dir / "biker.ply").string(), bad, std::cout);
    ADD_FAILURE() << "a malformed --cameras file was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("camera entry 0"), std::string::npos) << e.what();
  }
  EXPECT_THROW(choose_scene_frame(*model, "x.ply", (dir / "missing.json").string(), std::cout), std::runtime_error);
  // Found beside the scene: a warning naming it, and the content gives the first view.
  std::ostringstream log;
  const SceneFrame f = choose_scene_frame(*model, (dir / "biker.ply").string(), "", log);
  EXPECT_FALSE(f.training_view);
  EXPECT_NE(log.str().find("warning: ignoring"), std::string::npos) << log.str();
  EXPECT_NE(log.str().find(bad), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("first view: content"), std::string::npos) << log.str();
}

}  // namespace
