#include "splat_transform.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>

#include "camera/trace.h"
#include "common/image_io.h"
#include "renderer/renderer.h"
#include "scene/ply_io.h"
#include "scene/scene_bounds.h"

namespace catgs::test {

namespace {

std::string quoted(const std::string& s) { return "'" + s + "'"; }

}  // namespace

std::string splat_transform_missing() {
  const std::string node = CATGS_NODE_PATH;
  if (node.empty() || !std::filesystem::exists(node))
    return "node not found at configure time (apt-get install nodejs); splat-transform reference tests skipped";
  if (!std::filesystem::exists(CATGS_SPLAT_TRANSFORM))
    return std::string("splat-transform not installed (") + CATGS_SPLAT_TRANSFORM +
           " missing): run scripts/setup_web.sh; reference tests skipped";
  return "";
}

std::string splat_transform(const std::string& in, const std::string& out, const std::string& extra,
                            const std::string& actions) {
  const std::string cmd = quoted(CATGS_NODE_PATH) + " " + quoted(CATGS_SPLAT_TRANSFORM) + " -q -w " + extra + " " +
                          quoted(in) + " " + actions + " " + quoted(out) + " >/dev/null 2>&1";
  const int rc = std::system(cmd.c_str());
  if (rc != 0 || !std::filesystem::exists(out)) return cmd + " failed (status " + std::to_string(rc) + ")";
  return "";
}

std::vector<Camera> comparison_views(const GaussianModel& scene, const std::string& cameras_json) {
  std::vector<Camera> views;
  if (!cameras_json.empty()) {
    const auto cams = load_inria_cameras(cameras_json, 320, 212);
    for (std::size_t k : {0, 60, 120}) views.push_back(cams.at(std::min(k, cams.size() - 1)));
    return views;
  }
  GeneratorParams g;
  g.width = 320;
  g.height = 240;
  g.up = estimate_up(scene);
  g.duration_s = 1.0;
  g.rate_hz = 3.0;  // 4 samples over 360 degrees; the last repeats the first
  const Bounds rb = robust_bounds(scene);
  const glm::vec3 e = rb.extent();
  const float radius = 1.2f * std::max(e.x, std::max(e.y, e.z));
  const Trace orbit = make_orbit(rb, radius, 0.25f * radius, 360.0f, g);
  for (std::size_t k = 0; k < 3 && k < orbit.size(); ++k) views.push_back(orbit[k].camera);
  return views;
}

double min_render_psnr(const GaussianModel& a, const GaussianModel& b, const std::vector<Camera>& views) {
  auto ra = make_renderer("cpu", std::make_shared<GaussianModel>(a), {});
  auto rb = make_renderer("cpu", std::make_shared<GaussianModel>(b), {});
  double worst = 1e9;
  Image ia, ib;
  for (const Camera& cam : views) {
    ra->render(cam, ia);
    rb->render(cam, ib);
    worst = std::min(worst, psnr_rgba8(ia, ib));
  }
  return worst;
}

double psnr_against_reference_decode(const std::string& file, const std::string& dir, const std::string& cameras_json) {
  const std::string decoded = dir + "/reference_decode.ply";
  const std::string err = splat_transform(file, decoded);
  EXPECT_TRUE(err.empty()) << err;
  if (!err.empty()) return 0.0;
  const GaussianModel ours = load_scene(file);
  const GaussianModel reference = load_scene(decoded);
  EXPECT_EQ(ours.size(), reference.size());
  EXPECT_EQ(ours.sh_degree, reference.sh_degree);
  if (ours.size() != reference.size()) return 0.0;
  return min_render_psnr(ours, reference, comparison_views(reference, cameras_json));
}

}  // namespace catgs::test
