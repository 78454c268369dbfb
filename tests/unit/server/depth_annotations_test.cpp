// Issue 38: the depth under a pixel (render_core/cpu/pixel_depth.h, DepthRequest validation) and
// the annotations file beside a scene (server/session/annotations.h).
//
// Oracles: a synthetic wall of opaque flat Gaussians at a known plane (the probe's point must lie
// on the pixel's ray, written here from the field of view, where it meets the plane), and the CPU
// renderer's own transmittance (a render on white minus one on black) for the probe's opacity on
// the real biker scene.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>

#include <glm/gtc/quaternion.hpp>
#include <nlohmann/json.hpp>

#include "camera/camera.h"
#include "cpu/pixel_depth.h"
#include "renderer/renderer.h"
#include "session/access_tokens.h"
#include "session/annotations.h"
#include "process/first_view.h"
#include "proto/message_validation.h"
#include "session/rate_limit.h"
#include "test_data.h"

namespace {

using namespace catgs;
using namespace catgs::server;

constexpr float kWallZ = 5.0f;

// Flat, opaque Gaussians (std 0.15 in the plane, 0.005 across) every 0.15 units over
// [-half, half]^2 in the plane z = `z`: an opaque wall seen from the origin looking along +z.
void add_wall(GaussianModel& m, float z, float half, float opacity_logit) {
  const float step = 0.15f;
  const int n = static_cast<int>(std::floor(2 * half / step)) + 1;
  const std::size_t first = m.size();
  GaussianModel grown = m;
  grown.resize(first + static_cast<std::size_t>(n) * n);
  for (std::size_t i = 0; i < first; ++i) {  // resize() zeroes: copy the old rows back
    for (int k = 0; k < 3; ++k) {
      grown.means[3 * i + k] = m.means[3 * i + k];
      grown.log_scales[3 * i + k] = m.log_scales[3 * i + k];
      grown.sh[3 * i + k] = m.sh[3 * i + k];
    }
    for (int k = 0; k < 4; ++k) grown.rotations[4 * i + k] = m.rotations[4 * i + k];
    grown.opacity_logits[i] = m.opacity_logits[i];
  }
  std::size_t i = first;
  for (int a = 0; a < n; ++a)
    for (int b = 0; b < n; ++b, ++i) {
      grown.means[3 * i] = -half + step * static_cast<float>(a);
      grown.means[3 * i + 1] = -half + step * static_cast<float>(b);
      grown.means[3 * i + 2] = z;
      grown.log_scales[3 * i] = grown.log_scales[3 * i + 1] = std::log(0.15f);
      grown.log_scales[3 * i + 2] = std::log(0.005f);
      grown.rotations[4 * i] = 1.0f;
      grown.opacity_logits[i] = opacity_logit;
      grown.sh[3 * i] = 0.5f;  // DC: grey
    }
  m = std::move(grown);
}

GaussianModel walls(float front_logit) {
  GaussianModel m;
  m.name = "walls";
  add_wall(m, kWallZ, 3.0f, front_logit);
  add_wall(m, 8.0f, 3.0f, 6.0f);  // behind the front wall: hidden where the front one is opaque
  return m;
}

// Where the ray of pixel (x, y) of `c` meets the plane z = plane_z, from the camera's own
// definition (Camera::from_pose: square pixels, principal point at the centre, fy from the fov).
glm::vec3 ray_meets_plane(const glm::vec3& centre, const glm::quat& c2w, float fov_deg, int w, int h, double x,
                          double y, float plane_z) {
  const double f = h / (2.0 * std::tan(fov_deg * M_PI / 360.0));
  const glm::vec3 dir = glm::mat3_cast(c2w) *
                        glm::vec3(static_cast<float>((x - w / 2.0) / f), static_cast<float>((y - h / 2.0) / f), 1.0f);
  return centre + dir * ((plane_z - centre.z) / dir.z);
}

TEST(PixelDepth, OpaqueWallAtKnownDistance) {
  const GaussianModel m = walls(6.0f);  // alpha 0.99 at the centres
  const int w = 320, h = 240;
  const float fov = 50.0f;
  // Straight on, then from higher up and turned 15 degrees: the wall is then oblique to the view.
  struct Case {
    glm::vec3 centre;
    glm::quat c2w;
  };
  const Case cases[] = {{glm::vec3(0.0f), glm::quat(1, 0, 0, 0)},
                        {glm::vec3(0.0f, 0.5f, 0.0f), glm::angleAxis(glm::radians(-15.0f), glm::vec3(0, 1, 0))}};
  for (const Case& c : cases) {
    const Camera cam = Camera::from_pose(c.centre, c.c2w, fov, w, h);
    for (const auto& [x, y] : {std::pair{160.5, 120.5}, std::pair{100.25, 200.0}, std::pair{220.0, 60.0}}) {
      SCOPED_TRACE(testing::Message() << "camera at x " << c.centre.x << ", pixel " << x << ", " << y);
      const cpu::PixelDepth d = cpu::probe_pixel_depth(m, cam, x, y);
      ASSERT_TRUE(d.hit);
      const glm::vec3 want = ray_meets_plane(c.centre, c.c2w, fov, w, h, x, y, kWallZ);
      // Straight on every Gaussian lies at z = 5; obliquely the surface Gaussian is a neighbour
      // of the ray's crossing, within a spacing (0.15) times sin 15 degrees in depth.
      EXPECT_NEAR(d.point.x, want.x, 0.1f);
      EXPECT_NEAR(d.point.y, want.y, 0.1f);
      EXPECT_NEAR(d.point.z, want.z, 0.1f);
      EXPECT_GT(d.opacity, 0.99f);
      EXPECT_GE(d.contributors, 2u);
    }
  }
  // Straight on, the depth is the wall's exactly (every mean has z = 5), not the back wall's.
  const Camera straight = Camera::from_pose(glm::vec3(0.0f), glm::quat(1, 0, 0, 0), fov, w, h);
  EXPECT_FLOAT_EQ(cpu::probe_pixel_depth(m, straight, 100.5, 80.5).depth, kWallZ);
}

TEST(PixelDepth, NoSurfaceBesideTheWallsAndThroughThinOnes) {
  const GaussianModel m = walls(6.0f);
  // From 2 units away at 100 degrees the walls (6 units wide at z 5 and 8) fill only the middle.
  const Camera wide = Camera::from_pose(glm::vec3(0.0f), glm::quat(1, 0, 0, 0), 100.0f, 320, 240);
  const cpu::PixelDepth edge = cpu::probe_pixel_depth(m, wide, 0.5, 0.5);
  EXPECT_FALSE(edge.hit);
  EXPECT_LT(edge.opacity, 0.01f);
  // A faint front wall (opacity 0.018 a Gaussian, ~0.1 where they overlap) lets the ray through
  // to the back wall at z = 8.
  const GaussianModel faint = walls(-4.0f);
  const Camera straight = Camera::from_pose(glm::vec3(0.0f), glm::quat(1, 0, 0, 0), 50.0f, 320, 240);
  const cpu::PixelDepth through = cpu::probe_pixel_depth(faint, straight, 160.5, 120.5);
  ASSERT_TRUE(through.hit);
  EXPECT_FLOAT_EQ(through.depth, 8.0f);
  // Only the faint wall: no surface, and the opacity says how much it covers.
  GaussianModel only_faint;
  add_wall(only_faint, kWallZ, 3.0f, -4.0f);
  const cpu::PixelDepth thin = cpu::probe_pixel_depth(only_faint, straight, 160.5, 120.5);
  EXPECT_FALSE(thin.hit);
  EXPECT_GT(thin.opacity, 0.05f);
  EXPECT_LT(thin.opacity, 0.5f);
}

TEST(PixelDepth, RefusesPixelsOutsideTheView) {
  const GaussianModel m = walls(6.0f);
  const Camera cam = Camera::from_pose(glm::vec3(0.0f), glm::quat(1, 0, 0, 0), 50.0f, 64, 48);
  for (const auto& [x, y] :
       {std::pair{-0.1, 1.0}, std::pair{64.0, 1.0}, std::pair{1.0, 48.0}, std::pair{std::nan(""), 1.0}}) {
    EXPECT_THROW(cpu::probe_pixel_depth(m, cam, x, y), std::invalid_argument) << x << ", " << y;
  }
}

// The probe composites as the renderer does: its opacity (1 - T) equals the CPU renderer's
// transmittance at the same pixel, read from a render on a white and one on a black background.
TEST(PixelDepth, OpacityMatchesTheRenderersTransmittanceOnBiker) {
  auto model = test::cached_scene(test::bundled_scene());
  const SceneFrame frame = frame_from_content(*model);
  const int w = 160, h = 120;
  const CameraPose pose = first_view_pose(frame, w, h);
  const Camera cam = Camera::from_pose(pose.position, pose.orientation, pose.vertical_fov_deg, w, h);
  RenderOptions opt;
  opt.pipeline = Pipeline::exact;
  opt.speculation.task_splitting = false;  // one slice a tile: the probe's single ray
  Image black, white;
  make_renderer("cpu", model, opt)->render(cam, black);
  opt.background = glm::vec3(1.0f);
  make_renderer("cpu", model, opt)->render(cam, white);
  int hits = 0;
  const std::vector<fm::ChunkBounds> chunks = chunk_bounds_of(*model);
  for (int y = 5; y < h; y += 11)
    for (int x = 3; x < w; x += 13) {
      const cpu::PixelDepth d = cpu::probe_pixel_depth(*model, cam, x + 0.5, y + 0.5);
      // The chunk culling the server uses changes nothing.
      const cpu::PixelDepth culled = cpu::probe_pixel_depth(*model, cam, x + 0.5, y + 0.5, &chunks);
      EXPECT_EQ(culled.hit, d.hit);
      EXPECT_EQ(culled.depth, d.depth);
      EXPECT_EQ(culled.opacity, d.opacity);
      EXPECT_EQ(culled.contributors, d.contributors);
      const std::size_t p = (static_cast<std::size_t>(y) * w + x) * 3;
      const float T = white.rgb[p] - black.rgb[p];
      EXPECT_NEAR(d.opacity, 1.0f - T, 2e-3f) << "pixel " << x << ", " << y;
      if (std::fabs(T - 0.5f) > 0.01f) {
        EXPECT_EQ(d.hit, T < 0.5f) << "pixel " << x << ", " << y << " T " << T;
      }
      if (d.hit) {
        ++hits;
        // The point is on the biker: inside the bounds of its Gaussians.
        const Bounds b = model->bounds();
        for (int k = 0; k < 3; ++k) {
          EXPECT_GE(d.point[k], b.min[k]);
          EXPECT_LE(d.point[k], b.max[k]);
        }
      }
    }
  EXPECT_GT(hits, 5) << "the first view of the biker shows the biker";
}

pb::Pose pose_at(double x, double y, double z) {
  pb::Pose p;
  p.mutable_position()->set_x(x);
  p.mutable_position()->set_y(y);
  p.mutable_position()->set_z(z);
  p.mutable_orientation()->set_w(1.0);
  p.set_vertical_fov_deg(60.0);
  return p;
}

TEST(DepthRequestValidation, PixelInsideTheViewOfAPoseOrTheLastOne) {
  const Viewport viewport{640, 480};
  DepthQuery q;
  pb::DepthRequest r;
  r.set_x(10.5);
  r.set_y(20.5);
  auto bad = check_depth_request(r, std::nullopt, viewport, q);
  ASSERT_TRUE(bad);
  EXPECT_NE(bad->reason.find("before any Pose"), std::string::npos) << bad->reason;
  CameraPose last;
  last.position = glm::vec3(1, 2, 3);
  ASSERT_FALSE(check_depth_request(r, last, viewport, q));
  EXPECT_EQ(q.width, 640);
  EXPECT_EQ(q.pose.position, glm::vec3(1, 2, 3));
  *r.mutable_pose() = pose_at(4, 5, 6);
  r.set_width(100);
  r.set_height(50);
  ASSERT_FALSE(check_depth_request(r, last, viewport, q));
  EXPECT_EQ(q.pose.position, glm::vec3(4, 5, 6));
  EXPECT_EQ(q.width, 100);
  EXPECT_EQ(q.height, 50);
  EXPECT_EQ(q.x, 10.5);

  r.set_x(100.0);  // == width: outside
  bad = check_depth_request(r, last, viewport, q);
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->code, pb::ERROR_INVALID_ARGUMENT);
  EXPECT_NE(bad->reason.find("outside the 100x50 view"), std::string::npos) << bad->reason;
  r.set_x(std::numeric_limits<double>::quiet_NaN());
  bad = check_depth_request(r, last, viewport, q);
  ASSERT_TRUE(bad);
  EXPECT_NE(bad->reason.find("NaN"), std::string::npos) << bad->reason;
  r.set_x(1);
  r.set_width(5000);
  EXPECT_TRUE(check_depth_request(r, last, viewport, q));
  r.set_width(100);
  r.mutable_pose()->set_vertical_fov_deg(std::numeric_limits<double>::infinity());
  bad = check_depth_request(r, last, viewport, q);
  ASSERT_TRUE(bad);
  EXPECT_NE(bad->reason.find("DepthRequest pose"), std::string::npos) << bad->reason;
}

TEST(DepthRequestValidation, RateLimitsAndAuthorRole) {
  RateLimitSettings s;
  apply_rate_limits(s, "depth=2/3,save=off");
  EXPECT_EQ(s.depth.per_second, 2);
  EXPECT_EQ(s.depth.burst, 3);
  EXPECT_FALSE(s.save.enabled());
  EXPECT_THROW(apply_rate_limits(s, "depths=1/1"), std::invalid_argument);

  const std::string dir = test::temp_dir();
  std::ofstream(dir + "/tokens") << "viewer v1\nauthor a1\nadmin x1\n";
  AccessTokens t;
  t.add_file(dir + "/tokens");
  EXPECT_EQ(t.role_of("a1"), Role::author);
  EXPECT_TRUE(t.role_of("x1") >= Role::author) << "admin may do what an author may";
  EXPECT_FALSE(t.role_of("v1") >= Role::author);
}

const char* kGoodAnnotations = R"({
  "version": 1, "metres_per_unit": 0.5, "extra": "dropped",
  "hotspots": [
    {"id": "seat", "title": "Seat", "text": "leather", "position": [1, 2, 3],
     "view": {"position": [0, 0, -4], "orientation": [1, 0, 0, 0], "fov": 50}},
    {"id": "wheel", "title": "Wheel", "position": [-1, 0.5, 2]}
  ],
  "tour": ["wheel", "seat"]
})";

TEST(Annotations, NormalisedFormKeepsWhatTheFormatSays) {
  const auto j = nlohmann::json::parse(normalise_annotations(kGoodAnnotations, "a.json"));
  EXPECT_EQ(j["version"], 1);
  EXPECT_EQ(j["metres_per_unit"], 0.5);
  EXPECT_FALSE(j.contains("extra"));
  ASSERT_EQ(j["hotspots"].size(), 2u);
  EXPECT_EQ(j["hotspots"][0]["view"]["fov"], 50.0);
  EXPECT_EQ(j["hotspots"][1]["text"], "");
  EXPECT_FALSE(j["hotspots"][1].contains("view"));
  EXPECT_EQ(j["tour"][0], "wheel");
}

TEST(Annotations, GarbageGetsAnErrorNamingTheFileAndTheValue) {
  struct Case {
    const char* text;
    const char* says;
  };
  const Case cases[] = {
      {"\x01\x02 not json {", "not JSON"},
      {"[1, 2]", "top level"},
      {R"({"version": 2, "hotspots": []})", "version"},
      {R"({"version": 1})", "missing \"hotspots\""},
      {R"({"version": 1, "hotspots": [{"id": "a", "title": "A", "position": [1, 2]}]})", "hotspots[0].position"},
      {R"({"version": 1, "hotspots": [{"id": "a", "title": "", "position": [1, 2, 3]}]})", "hotspots[0].title"},
      {R"({"version": 1, "hotspots": [{"id": "a", "title": "A", "position": [1, 2, 1e300]}]})", "position[2]"},
      {R"({"version": 1, "hotspots": [{"id": "a", "title": "A", "position": [1, 2, 3],
          "view": {"position": [0, 0, 0], "orientation": [0, 0, 0, 0], "fov": 50}}]})",
       "zero quaternion"},
      {R"({"version": 1, "hotspots": [{"id": "a", "title": "A", "position": [1, 2, 3]},
                                       {"id": "a", "title": "B", "position": [1, 2, 3]}]})",
       "hotspots[1].id"},
      {R"({"version": 1, "hotspots": [], "tour": ["nope"]})", "tour[0]"},
      {R"({"version": 1, "hotspots": [], "metres_per_unit": -1})", "metres_per_unit"},
  };
  for (const Case& c : cases) {
    try {
      normalise_annotations(c.text, "scene.hotspots.json");
      ADD_FAILURE() << "accepted: " << c.text;
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.rfind("scene.hotspots.json: ", 0), 0u) << what;
      EXPECT_NE(what.find(c.says), std::string::npos) << what;
    }
  }
}

TEST(Annotations, FileBesideTheSceneReadWrittenAndGarbageLeftAlone) {
  const std::string dir = test::temp_dir();
  const std::string scene = dir + "/biker.compressed.ply";
  EXPECT_EQ(annotations_path(scene), dir + "/biker.compressed.hotspots.json");
  AnnotationsFile none = read_annotations(scene);
  EXPECT_TRUE(none.json.empty() && none.error.empty()) << "no file: no annotations, no error";

  std::ofstream(annotations_path(scene)) << "{\"version\": 1, \"hotspots\": [oops]}";
  const AnnotationsFile garbage = read_annotations(scene);
  EXPECT_TRUE(garbage.json.empty());
  EXPECT_NE(garbage.error.find(annotations_path(scene)), std::string::npos) << garbage.error;
  EXPECT_NE(garbage.error.find("not JSON"), std::string::npos) << garbage.error;

  // Too large: refused by its size, unread.
  std::ofstream(annotations_path(scene)) << std::string(kMaxAnnotationsBytes + 1, ' ');
  EXPECT_NE(read_annotations(scene).error.find("bytes, at most"), std::string::npos);

  const std::string saved = write_annotations(scene, kGoodAnnotations);
  std::ifstream in(annotations_path(scene));
  const auto on_disk = nlohmann::json::parse(in);
  EXPECT_EQ(on_disk, nlohmann::json::parse(saved));
  EXPECT_EQ(on_disk["hotspots"][0]["position"][2], 3.0);
  EXPECT_EQ(read_annotations(scene).json, saved);

  // An invalid save writes nothing: the file keeps the last good one.
  EXPECT_THROW(write_annotations(scene, "{\"version\": 1}"), std::invalid_argument);
  EXPECT_EQ(read_annotations(scene).json, saved);
  // A folder that cannot take the file: a runtime_error naming it.
  EXPECT_THROW(write_annotations(dir + "/missing/x.ply", kGoodAnnotations), std::runtime_error);
}

}  // namespace
