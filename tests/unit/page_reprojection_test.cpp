// tools/shown/page_reprojection.h against the page's own reproject.js (run by node through
// page_reprojection_ref.mjs): the same homographies, plane depths and edge-fill bytes; and
// shown_picture against the exact picture of a textured plane.
#include "shown/page_reprojection.h"
#include "shown/depth_warp.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "camera/camera.h"
#include "forward_model/depth_grid.h"
#include "renderer/renderer.h"

namespace catgs::shown {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr double kPi = 3.141592653589793;

// ---- poses -----------------------------------------------------------------------------------

glm::dquat turn(const glm::dvec3& axis, double radians) { return glm::angleAxis(radians, glm::normalize(axis)); }

glm::dvec3 axis_of(const PagePose& p, int k) {
  glm::dvec3 e(0.0);
  e[k] = 1.0;
  return qrotate(p.orientation, e);
}

// A camera at (0.3, -0.2, -4) in a general orientation (no axis-aligned shortcuts), fov 50.
PagePose base_pose() {
  PagePose p;
  p.position = {0.3, -0.2, -4.0};
  p.orientation = turn({1.0, 2.0, 3.0}, 0.35);
  p.fov_deg = 50.0;
  return p;
}

PagePose turned(PagePose p, double radians) {
  p.orientation = turn(axis_of(p, 1), radians) * p.orientation;  // about the camera's down axis: a yaw
  return p;
}

PagePose tilted(PagePose p, double radians) {
  p.orientation = turn(axis_of(p, 0), radians) * p.orientation;  // about the camera's right axis: a pitch
  return p;
}

PagePose moved(PagePose p, int axis, double distance) {
  p.position += distance * axis_of(p, axis);
  return p;
}

json pose_json(const PagePose& p) {
  return {{"position", {p.position.x, p.position.y, p.position.z}},
          {"orientation", {p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z}},
          {"fovDeg", p.fov_deg}};
}

// ---- images ----------------------------------------------------------------------------------

Image rgba8_image(int w, int h) {
  Image img;
  img.width = w;
  img.height = h;
  img.rgba8.assign(static_cast<std::size_t>(w) * h * 4, 255);
  return img;
}

void set_rgb(Image& img, int x, int y, int r, int g, int b) {
  const std::size_t o = (static_cast<std::size_t>(y) * img.width + x) * 4;
  img.rgba8[o] = static_cast<uint8_t>(r);
  img.rgba8[o + 1] = static_cast<uint8_t>(g);
  img.rgba8[o + 2] = static_cast<uint8_t>(b);
}

// A w x h picture with a gradient, a sharp cross and a checkered block (nothing black).
Image synthetic(int w, int h) {
  Image img = rgba8_image(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      int r = 40 + 200 * x / w, g = 30 + 200 * y / h, b = 90;
      if (x == w / 3 || y == h / 2) r = g = b = 250;
      if (x > 2 * w / 3 && y < h / 3 && (x + y) % 2 == 0) b = 10;
      set_rgb(img, x, y, r, g, b);
    }
  return img;
}

json image_json(const Image& img) { return {{"width", img.width}, {"height", img.height}, {"data", img.rgba8}}; }

// ---- node ------------------------------------------------------------------------------------

std::string node_missing() {
  const std::string node = CATGS_NODE_PATH;
  if (node.empty() || !fs::exists(node))
    return "node not found at configure time (apt-get install nodejs); the page's reproject.js cannot run";
  return "";
}

fs::path ref_script() { return fs::path(__FILE__).parent_path() / "page_reprojection_ref.mjs"; }

// Runs the page's module on `job`; fills `result` and returns "" or says what went wrong.
std::string run_page(const json& job, json& result) {
  const fs::path dir = fs::temp_directory_path() / ("catgs_page_reproj_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path in = dir / "job.json", err = dir / "stderr.txt";
  std::ofstream(in) << job.dump();
  const std::string cmd = "'" + std::string(CATGS_NODE_PATH) + "' '" + ref_script().string() + "' '" + in.string() +
                          "' 2>'" + err.string() + "'";
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return "popen failed: " + cmd;
  std::string out;
  char buf[65536];
  for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, pipe)) > 0;) out.append(buf, n);
  const int rc = ::pclose(pipe);
  std::stringstream why;
  why << std::ifstream(err).rdbuf();
  fs::remove_all(dir);
  if (rc != 0) return cmd + " failed (status " + std::to_string(rc) + "): " + why.str();
  result = json::parse(out, nullptr, false);
  if (result.is_discarded()) return "node printed no JSON: " + out.substr(0, 200);
  return "";
}

#define REQUIRE_NODE() \
  if (const std::string why = node_missing(); !why.empty()) GTEST_SKIP() << why

// |a - b| relative to the larger magnitude (exact zeros must match exactly).
double rel_diff(double a, double b) {
  const double scale = std::max(std::abs(a), std::abs(b));
  return scale == 0.0 ? 0.0 : std::abs(a - b) / scale;
}

double max_rel_diff(const Mat3& ours, const json& theirs) {
  double worst = 0.0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) worst = std::max(worst, rel_diff(ours[i][j], theirs.at(i).at(j).get<double>()));
  return worst;
}

// ---- the cases -------------------------------------------------------------------------------

struct PosePair {
  std::string name;
  PagePose from, to;
  double depth;
  int width, height;
  bool behind;  // a corner of the frame falls behind `to`
};

std::vector<PosePair> pose_pairs() {
  const PagePose a = base_pose();
  PagePose zoom = moved(a, 2, 0.5);
  zoom.fov_deg = 38.0;
  PagePose all = moved(moved(turned(a, -0.2), 0, -0.3), 1, 0.15);
  all.fov_deg = 64.0;
  return {
      {"pure turn", a, turned(a, 0.15), 4.0, 640, 480, false},
      {"step sideways", a, moved(a, 0, 0.4), 4.0, 1280, 720, false},
      {"step forward", a, moved(a, 2, 0.8), 4.0, 640, 480, false},
      {"step back (zoom out)", a, moved(a, 2, -1.5), 3.0, 401, 233, false},
      {"other fov", a, zoom, 2.5, 320, 240, false},
      {"turn + step + fov", a, all, 6.0, 40, 24, false},
      {"identity", a, a, 4.0, 640, 480, false},
      {"large turn, corner behind", a, turned(a, 1.6), 4.0, 640, 480, true},
  };
}

TEST(PageReprojection, MatchesThePagesHomographiesAndDepths) {
  REQUIRE_NODE();
  const auto pairs = pose_pairs();
  json job;
  job["reprojections"] = json::array();
  for (const auto& p : pairs)
    job["reprojections"].push_back({{"from", pose_json(p.from)},
                                    {"to", pose_json(p.to)},
                                    {"planeDepth", p.depth},
                                    {"width", p.width},
                                    {"height", p.height}});
  const PagePose a = base_pose();
  const glm::dvec3 fwd = axis_of(a, 2);
  const std::vector<std::pair<glm::dvec3, double>> targets = {
      {a.position + 4.0 * fwd, 1.0},                        // straight ahead
      {a.position + 2.5 * fwd + 0.7 * axis_of(a, 0), 1.0},  // off axis
      {a.position - 3.0 * fwd, 7.5},                        // behind: the fallback
      {a.position + 1e-7 * fwd, 2.0},                       // at the camera: the fallback
      {glm::dvec3(0.0), 1.0},                               // the world origin
  };
  job["depths"] = json::array();
  for (const auto& [t, fb] : targets)
    job["depths"].push_back({{"pose", pose_json(a)}, {"target", {t.x, t.y, t.z}}, {"fallback", fb}});
  json res;
  const std::string err = run_page(job, res);
  ASSERT_TRUE(err.empty()) << err;

  double worst_h = 0.0, worst_corner = 0.0, worst_inv = 0.0;
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    const auto& p = pairs[k];
    SCOPED_TRACE(p.name);
    const json& r = res.at("reprojections").at(k);
    const Mat3 H = plane_reprojection(p.from, p.to, p.depth, p.width, p.height);
    const double dh = max_rel_diff(H, r.at("H"));
    worst_h = std::max(worst_h, dh);
    EXPECT_LE(dh, 1e-9);
    const double w = p.width, h = p.height;
    const std::array<std::array<double, 2>, 4> corners = {{{0.0, 0.0}, {w, 0.0}, {w, h}, {0.0, h}}};
    bool any_behind = false;
    for (std::size_t c = 0; c < 4; ++c) {
      const auto ours = apply_homography(H, corners[c][0], corners[c][1]);
      const json& theirs = r.at("corners").at(c);
      ASSERT_EQ(ours.has_value(), !theirs.is_null()) << "corner " << c;
      any_behind = any_behind || !ours;
      if (!ours) continue;
      for (std::size_t i = 0; i < 2; ++i) {
        // Relative to the image size: a corner near 0 has no scale of its own.
        const double d = std::abs((*ours)[i] - theirs.at(i).get<double>()) / std::max(w, h);
        worst_corner = std::max(worst_corner, d);
        EXPECT_LE(d, 1e-9);
      }
    }
    EXPECT_EQ(any_behind, p.behind);
    const auto inv = invert3(H);
    ASSERT_EQ(inv.has_value(), !r.at("inverse").is_null());
    if (inv) {
      worst_inv = std::max(worst_inv, max_rel_diff(*inv, r.at("inverse")));
      EXPECT_LE(max_rel_diff(*inv, r.at("inverse")), 1e-9);
    }
  }
  double worst_depth = 0.0;
  for (std::size_t k = 0; k < targets.size(); ++k) {
    const double ours = plane_depth_for(a, targets[k].first, targets[k].second);
    const double d = rel_diff(ours, res.at("depths").at(k).get<double>());
    worst_depth = std::max(worst_depth, d);
    EXPECT_LE(d, 1e-12) << "depth case " << k;
  }
  EXPECT_EQ(plane_depth_for(a, targets[2].first, 7.5), 7.5);
  EXPECT_EQ(plane_depth_for(a, targets[3].first, 2.0), 2.0);
  std::printf(
      "[ page    ] max relative difference from node: H %.3g, corners %.3g (of the image size), H^-1 %.3g, "
      "plane depth %.3g\n",
      worst_h, worst_corner, worst_inv, worst_depth);
}

TEST(PageReprojection, EdgeFillBytesMatchThePage) {
  REQUIRE_NODE();
  const PagePose a = base_pose();
  struct Case {
    std::string name;
    PagePose to;
    int width, height;  // the canvas
    Image src;          // the frame at backdrop size
    int out_w, out_h;
  };
  const Image src = synthetic(40, 24);
  const std::vector<Case> cases = {
      {"turn, canvas 10x the backdrop", turned(a, 0.25), 400, 240, src, 40, 24},
      {"step sideways", moved(a, 0, 0.6), 40, 24, src, 40, 24},
      {"zoom out: all four edges", moved(a, 2, -2.0), 40, 24, src, 40, 24},
      {"turn + climb, half-size source", moved(turned(a, -0.3), 1, -0.5), 40, 24, synthetic(20, 12), 40, 24},
      {"tilted, out larger than src", tilted(a, 0.2), 40, 24, src, 60, 36},
      {"corner behind: false, out untouched", turned(a, 1.6), 40, 24, src, 40, 24},
  };
  json job;
  job["edgeFills"] = json::array();
  std::vector<Image> outs;
  std::vector<bool> oks;
  for (const auto& c : cases) {
    const Mat3 H = plane_reprojection(a, c.to, 4.0, c.width, c.height);
    Image out = rgba8_image(c.out_w, c.out_h);
    std::fill(out.rgba8.begin(), out.rgba8.end(), uint8_t{7});  // shows what edgeFill left alone
    job["edgeFills"].push_back({{"from", pose_json(a)},
                                {"to", pose_json(c.to)},
                                {"planeDepth", 4.0},
                                {"width", c.width},
                                {"height", c.height},
                                {"H", H},
                                {"src", image_json(c.src)},
                                {"out", image_json(out)}});
    oks.push_back(edge_fill(H, c.width, c.height, c.src, out));
    outs.push_back(out);
  }
  json res;
  const std::string err = run_page(job, res);
  ASSERT_TRUE(err.empty()) << err;
  std::size_t differing = 0, differing_own = 0;
  for (std::size_t k = 0; k < cases.size(); ++k) {
    SCOPED_TRACE(cases[k].name);
    const json& r = res.at("edgeFills").at(k);
    EXPECT_EQ(oks[k], r.at("ok").get<bool>());
    EXPECT_EQ(oks[k], r.at("okOwnH").get<bool>());
    const auto theirs = r.at("data").get<std::vector<uint8_t>>();
    const auto theirs_own = r.at("dataOwnH").get<std::vector<uint8_t>>();
    ASSERT_EQ(outs[k].rgba8.size(), theirs.size());
    for (std::size_t i = 0; i < theirs.size(); ++i) {
      differing += outs[k].rgba8[i] != theirs[i];
      differing_own += outs[k].rgba8[i] != theirs_own[i];
    }
    EXPECT_EQ(outs[k].rgba8, theirs) << "with the same H";
    EXPECT_EQ(outs[k].rgba8, theirs_own) << "with the page's own reprojection()";
    // Not a trivial pass: the filled cases moved something, the refused one left the 7s.
    const bool all_sevens = std::all_of(theirs.begin(), theirs.end(), [](uint8_t v) { return v == 7; });
    EXPECT_EQ(all_sevens, !oks[k]);
  }
  EXPECT_FALSE(oks.back());
  std::printf("[ page    ] edgeFill bytes differing from node: %zu (same H), %zu (the page's own H)\n", differing,
              differing_own);
}

// ---- shown_picture against the exact picture of a textured plane ---------------------------------

// A smooth texture on the plane z = kDepth (world units; periods of 12 to 20 pixels at 160x120
// from the origin), never black.
constexpr double kDepth = 2.0;

std::array<int, 3> texture(double X, double Y) {
  const auto wave = [](double v, double period) { return std::sin(2.0 * kPi * v / period); };
  return {static_cast<int>(std::lround(128.0 + 90.0 * wave(X, 0.25))),
          static_cast<int>(std::lround(128.0 + 90.0 * wave(Y, 0.3))),
          static_cast<int>(std::lround(128.0 + 60.0 * wave(X + Y, 0.4)))};
}

// The exact picture of the plane from `pose` (each pixel centre's ray, to the plane).
Image plane_picture(const PagePose& pose, int w, int h) {
  Image img = rgba8_image(w, h);
  const Intrinsics k = intrinsics_for(pose.fov_deg, w, h);
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const glm::dvec3 cam((i + 0.5 - k.cx) / k.fx, (j + 0.5 - k.cy) / k.fy, 1.0);
      const glm::dvec3 ray = qrotate(pose.orientation, cam);
      const double s = (kDepth - pose.position.z) / ray.z;
      const auto c = texture(pose.position.x + s * ray.x, pose.position.y + s * ray.y);
      set_rgb(img, i, j, c[0], c[1], c[2]);
    }
  return img;
}

// Mean and max |difference| over R, G, B of the pixels at least `margin` from every border.
std::pair<double, int> difference(const Image& a, const Image& b, int margin) {
  double sum = 0.0;
  int worst = 0;
  std::size_t n = 0;
  for (int y = margin; y < a.height - margin; ++y)
    for (int x = margin; x < a.width - margin; ++x)
      for (int c = 0; c < 3; ++c) {
        const std::size_t o = (static_cast<std::size_t>(y) * a.width + x) * 4 + c;
        const int d = std::abs(int(a.rgba8[o]) - int(b.rgba8[o]));
        sum += d;
        worst = std::max(worst, d);
        ++n;
      }
  return {sum / static_cast<double>(n), worst};
}

PagePose camera_a() {
  PagePose p;  // at the origin, looking down +z at the plane
  p.fov_deg = 60.0;
  return p;
}

TEST(ShownPicture, SamePoseIsTheFrameBitForBit) {
  const PagePose a = camera_a();
  const Image frame = plane_picture(a, 160, 120);
  const Image shown = shown_picture(frame, a, a, kDepth);
  EXPECT_EQ(shown.width, 160);
  EXPECT_EQ(shown.height, 120);
  EXPECT_EQ(shown.rgba8, frame.rgba8);
}

TEST(ShownPicture, PlaneAtItsDepthLandsWhereTheNewCameraSeesIt) {
  const PagePose a = camera_a();
  const Image frame = plane_picture(a, 160, 120);
  PagePose sideways = a;
  sideways.position.x = 0.2;  // about 10 pixels of parallax at the plane
  PagePose forward = a;
  forward.position.z = 0.3;
  PagePose turned_a = turned(a, 0.08);
  turned_a.position = {0.05, -0.04, 0.1};
  turned_a.fov_deg = 55.0;
  for (const auto& [name, to] : std::vector<std::pair<std::string, PagePose>>{
           {"sideways", sideways}, {"forward", forward}, {"turn + step + fov", turned_a}}) {
    SCOPED_TRACE(name);
    const Image truth = plane_picture(to, 160, 120);
    const auto [mean, worst] = difference(shown_picture(frame, a, to, kDepth), truth, 16);
    std::printf("[ shown   ] %s at the plane's depth: mean |diff| %.2f, max %d (of 255)\n", name.c_str(), mean, worst);
    EXPECT_LT(mean, 1.5);
    EXPECT_LE(worst, 8);
    // Without re-projection (the stale frame as it was) the same comparison is far off.
    EXPECT_GT(difference(frame, truth, 16).first, 10.0);
  }
  // A wrong plane depth puts the sideways step's parallax wrong by two thirds: clearly worse.
  const Image truth = plane_picture(sideways, 160, 120);
  const double wrong = difference(shown_picture(frame, a, sideways, 3.0 * kDepth), truth, 16).first;
  const double right = difference(shown_picture(frame, a, sideways, kDepth), truth, 16).first;
  std::printf("[ shown   ] sideways, plane at 3x its depth: mean |diff| %.2f (right depth %.2f)\n", wrong, right);
  EXPECT_GT(wrong, 10.0 * right);
  EXPECT_GT(wrong, 10.0);
}

TEST(ShownPicture, UncoveredEdgeContinuesTheFrameNeverBlack) {
  // 800x600: the backdrop is the frame shrunk to 256x192 (display.js's limit).
  const PagePose a = camera_a();
  const Image frame = plane_picture(a, 800, 600);
  const PagePose to = turned(a, 30.0 * kPi / 180.0);  // a large turn right: the right third uncovered
  const Mat3 H = plane_reprojection(a, to, kDepth, 800, 600);
  ASSERT_TRUE(apply_homography(H, 800.0, 300.0));
  ASSERT_LT((*apply_homography(H, 800.0, 300.0))[0], 560.0) << "the frame's right edge moves well into the view";
  const Image shown = shown_picture(frame, a, to, kDepth);
  ASSERT_EQ(shown.rgba8.size(), frame.rgba8.size());
  std::size_t black = 0;
  for (std::size_t o = 0; o < shown.rgba8.size(); o += 4)
    black += shown.rgba8[o] == 0 && shown.rgba8[o + 1] == 0 && shown.rgba8[o + 2] == 0;
  EXPECT_EQ(black, 0u);
  EXPECT_NE(shown.rgba8, frame.rgba8);
  // The uncovered column at the right edge continues the frame's last column: the shown pixel at
  // (799, 300) is close to the frame's right edge near its middle row (the outline's nearest point).
  const std::size_t at = (300u * 800u + 799u) * 4u;
  const auto edge = sample_bilinear(frame, 799.5, 300.0);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(shown.rgba8[at + c], edge[c], 40.0) << "channel " << c;
}

TEST(ShownPicture, CornerBehindShowsThePlainFrame) {
  const PagePose a = camera_a();
  const Image frame = plane_picture(a, 160, 120);
  const PagePose to = turned(a, 1.6);
  const Mat3 H = plane_reprojection(a, to, kDepth, 160, 120);
  ASSERT_FALSE(apply_homography(H, 0.0, 0.0)) << "a turn right of 92 degrees: the left edge is behind";
  ASSERT_TRUE(apply_homography(H, 160.0, 0.0));
  EXPECT_EQ(shown_picture(frame, a, to, kDepth).rgba8, frame.rgba8);
}

TEST(PageDepthWarp, MatchesThePagesMeshVertices) {
  REQUIRE_NODE();
  json job;
  job["warps"] = json::array();
  std::vector<DepthGrid> grids;
  const auto pairs = pose_pairs();
  for (const auto& p : pairs) {
    // A grid of cell 48 over the case's size: depths from 0.6 to 12, every fifth vertex without a
    // surface (the plane's depth then).
    DepthGrid g;
    g.cell = 48;
    g.cols = fm::depth_grid_cols(p.width, g.cell);
    g.rows = fm::depth_grid_rows(p.height, g.cell);
    json depths = json::array();
    for (int i = 0; i < g.cols * g.rows; ++i) {
      const float z = i % 5 == 2 ? INFINITY : 0.6f + 0.37f * static_cast<float>(i % 31);
      g.depth.push_back(z);
      depths.push_back(std::isfinite(z) ? json(z) : json(nullptr));
    }
    grids.push_back(g);
    job["warps"].push_back({{"from", pose_json(p.from)},
                            {"to", pose_json(p.to)},
                            {"planeDepth", p.depth},
                            {"width", p.width},
                            {"height", p.height},
                            {"grid", {{"cols", g.cols}, {"rows", g.rows}, {"cell", g.cell}, {"depth", depths}}}});
  }
  json page;
  const std::string why = run_page(job, page);
  ASSERT_EQ(why, "");
  double worst_px = 0.0, worst_rel = 0.0;
  for (std::size_t c = 0; c < pairs.size(); ++c) {
    const auto& p = pairs[c];
    const std::vector<WarpVertex> ours = warp_vertices(p.from, p.to, grids[c], p.depth, p.width, p.height);
    const json& theirs = page.at("warps").at(c);
    ASSERT_EQ(theirs.at("sx").size(), ours.size()) << p.name;
    std::vector<std::uint32_t> triangles;
    for (std::size_t i = 0; i < ours.size(); ++i) {
      const WarpVertex& v = ours[i];
      worst_px = std::max(
          {worst_px, std::abs(v.sx - theirs["sx"][i].get<double>()), std::abs(v.sy - theirs["sy"][i].get<double>())});
      worst_rel = std::max({worst_rel, rel_diff(v.clip_w, theirs["clipW"][i].get<double>()),
                            rel_diff(v.inv_z, theirs["invZ"][i].get<double>())});
      EXPECT_EQ(v.u, theirs["u"][i].get<double>()) << p.name;
      EXPECT_EQ(v.v, theirs["v"][i].get<double>()) << p.name;
    }
    // The triangles the page draws: two a cell, those with every vertex in front.
    const int cols = grids[c].cols;
    for (int l = 0; l + 1 < grids[c].rows; ++l)
      for (int k = 0; k + 1 < cols; ++k) {
        const auto a = static_cast<std::uint32_t>(l * cols + k), b = a + 1, cc = a + static_cast<std::uint32_t>(cols),
                   d = cc + 1;
        const auto front = [&](std::uint32_t i) { return ours[i].clip_w > 1e-9; };
        if (front(a) && front(b) && front(d)) triangles.insert(triangles.end(), {a, b, d});
        if (front(a) && front(d) && front(cc)) triangles.insert(triangles.end(), {a, d, cc});
      }
    EXPECT_EQ(theirs.at("triangles").get<std::vector<std::uint32_t>>(), triangles) << p.name;
  }
  std::printf("[ page    ] depth warp vertices: max difference from node %.3g px, %.3g relative (clip w, 1/z)\n",
              worst_px, worst_rel);
  EXPECT_LT(worst_px, 1e-6);
  EXPECT_LT(worst_rel, 1e-9);
}

TEST(PageReprojection, PagePoseOfACameraAndTheBackdropSize) {
  const PagePose p = base_pose();
  const glm::quat q(static_cast<float>(p.orientation.w), static_cast<float>(p.orientation.x),
                    static_cast<float>(p.orientation.y), static_cast<float>(p.orientation.z));
  const Camera cam = Camera::from_pose(glm::vec3(p.position), q, 50.0f, 640, 480);
  const PagePose back = page_pose_of(cam);
  EXPECT_NEAR(glm::length(back.position - p.position), 0.0, 1e-5);
  EXPECT_NEAR(std::abs(glm::dot(back.orientation, p.orientation)), 1.0, 1e-6);
  EXPECT_NEAR(back.fov_deg, 50.0, 1e-4);
  // display.js _fillBackdrop: at most 256 across, Math.round, at least 1.
  EXPECT_EQ(backdrop_size(1920, 1080).width, 256);
  EXPECT_EQ(backdrop_size(1920, 1080).height, 144);
  EXPECT_EQ(backdrop_size(200, 100).width, 200);
  EXPECT_EQ(backdrop_size(3000, 10).height, 1);
  EXPECT_EQ(backdrop_size(1000, 250).height, 64);
  // The area average: 4x2 -> 2x1 is the mean of each 2x2 block; 3 -> 2 weights a split pixel half.
  Image img = rgba8_image(4, 2);
  for (int x = 0; x < 4; ++x)
    for (int y = 0; y < 2; ++y) set_rgb(img, x, y, 10 * x + y, 100, 200 - x);
  const Image half = shrink_area_average(img, 2, 1);
  EXPECT_EQ(half.rgba8, (std::vector<uint8_t>{6, 100, 200, 255, 26, 100, 198, 255}));  // 5.5 -> 6, 25.5 -> 26
  Image three = rgba8_image(3, 1);
  for (int x = 0; x < 3; ++x) set_rgb(three, x, 0, 30 * x, 0, 0);
  EXPECT_EQ(shrink_area_average(three, 2, 1).rgba8, (std::vector<uint8_t>{10, 0, 0, 255, 50, 0, 0, 255}));
}

}  // namespace
}  // namespace catgs::shown
