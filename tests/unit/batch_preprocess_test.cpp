// Stage 1 for a batch of views (cpu::preprocess_batch, the mirror of the CUDA core's
// preprocess_batch; issue 47): each view's results equal cpu::preprocess's for that view alone,
// on the bundled scene, on a real scene along its own camera path (views spread as sessions
// would be), and with a level of detail cut.
#include <cstring>

#include <gtest/gtest.h>

#include "camera/trace.h"
#include "cpu/cpu_renderer.h"
#include "forward_model/chunk_bounds.h"
#include "lod/lod_build.h"
#include "scene/scene_bounds.h"
#include "test_data.h"

namespace catgs {
namespace {

template <class T>
bool same_bits(const T& a, const T& b) {
  return std::memcmp(&a, &b, sizeof(T)) == 0;
}

// Expects `batch` to hold what `single` holds: the same tile counts for every Gaussian and, for
// the listed ones (the later stages read nothing else), the same features bit for bit. Returns
// how many Gaussians were listed.
std::size_t expect_same(const cpu::ProjectedGaussians& batch, const cpu::ProjectedGaussians& single,
                        const std::string& what) {
  EXPECT_EQ(batch.tiles_touched, single.tiles_touched) << what;
  std::size_t listed = 0, differ = 0;
  for (std::size_t i = 0; i < single.tiles_touched.size(); ++i) {
    if (single.tiles_touched[i] == 0) continue;
    ++listed;
    const bool same = same_bits(batch.mean2d[i], single.mean2d[i]) && same_bits(batch.conic[i], single.conic[i]) &&
                      same_bits(batch.opacity[i], single.opacity[i]) && same_bits(batch.depth[i], single.depth[i]) &&
                      same_bits(batch.q_max[i], single.q_max[i]) && same_bits(batch.color[i], single.color[i]) &&
                      same_bits(batch.tile_rect[i], single.tile_rect[i]);
    differ += same ? 0 : 1;
  }
  EXPECT_EQ(differ, 0u) << what << ": listed Gaussians whose features differ";
  return listed;
}

// Pre-processes `views` of `m` as one batch and one at a time, for both stage-1 pipelines, and
// compares; expects every view to list something.
void expect_batch_equals_single(const GaussianModel& m, const std::vector<Camera>& views, float lod_error_px) {
  const std::vector<fm::ChunkBounds> chunks = chunk_bounds_of(m);
  for (Pipeline p : {Pipeline::exact, Pipeline::vanilla}) {
    std::vector<cpu::ProjectedGaussians> batch(views.size());
    std::vector<cpu::ProjectedGaussians*> outs;
    for (auto& b : batch) outs.push_back(&b);
    cpu::preprocess_batch(m, chunks, views, p, outs, lod_error_px);
    for (std::size_t k = 0; k < views.size(); ++k) {
      cpu::ProjectedGaussians single;
      cpu::preprocess(m, chunks, views[k], p, single, fm::kAllTiles, lod_error_px);
      const std::string what = std::string(p == Pipeline::exact ? "exact" : "vanilla") + " view " + std::to_string(k);
      EXPECT_GT(expect_same(batch[k], single, what), 0u) << what << " lists nothing: a weak test";
    }
  }
}

// `count` views spread evenly along `trace`.
std::vector<Camera> spread(const Trace& trace, std::size_t count) {
  std::vector<Camera> views;
  for (std::size_t k = 0; k < count; ++k) views.push_back(trace[k * trace.size() / count].camera);
  return views;
}

// 16 poses at 320x180 around `m`, `distance` and `height` times its extent out and up.
Trace orbit_of(const GaussianModel& m, float distance, float height) {
  GeneratorParams g;
  g.width = 320;
  g.height = 180;
  g.rate_hz = 16.0;
  g.duration_s = 1.0;
  const Bounds b = m.bounds();
  return make_orbit(b, distance * glm::length(b.extent()), height * glm::length(b.extent()), 360.0f, g);
}

TEST(BatchPreprocess, EqualsOneViewAtATimeOnTheBundledScene) {
  const auto m = test::cached_scene(test::bundled_scene());
  expect_batch_equals_single(*m, spread(orbit_of(*m, 0.6f, 0.1f), 8), 0.0f);
}

TEST(BatchPreprocess, EqualsOneViewAtATimeOnARealPath) {
  CATGS_REQUIRE_DATA(scene, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cameras, "traces/flowers_sh3.cameras.json");
  const auto m = test::cached_scene(scene);
  const Trace path = interpolate_views(load_inria_cameras(cameras, 320, 180), 30.0, 0.5);
  ASSERT_GE(path.size(), 16u);
  expect_batch_equals_single(*m, spread(path, 16), 0.0f);
}

TEST(BatchPreprocess, EqualsOneViewAtATimeWithALevelOfDetailCut) {
  const auto m = test::cached_scene(test::bundled_scene());
  const GaussianModel with_lod = build_lod(*m);
  // Far enough out that the cut at 4 px draws coarser levels for some views.
  const std::vector<Camera> views = spread(orbit_of(*m, 1.5f, 0.2f), 6);
  const fm::LodCut cut = fm::lod_cut(with_lod.lod, fm::view_of(views[0]), 4.0f);
  std::size_t skipped = 0;
  for (std::size_t c = 0; c < with_lod.lod.size(); ++c) skipped += cut.drawn(c) ? 0 : 1;
  EXPECT_GT(skipped, 0u) << "the cut should leave some chunks to other levels";
  expect_batch_equals_single(with_lod, views, 4.0f);
}

TEST(BatchPreprocess, RefusesMismatchedOutputs) {
  const auto m = test::cached_scene(test::bundled_scene());
  const std::vector<fm::ChunkBounds> chunks = chunk_bounds_of(*m);
  const Camera cam = Camera::from_pose(glm::vec3(0.0f, 0.0f, -3.0f), glm::quat(1, 0, 0, 0), 50.0f, 64, 64);
  cpu::ProjectedGaussians out;
  EXPECT_THROW(cpu::preprocess_batch(*m, chunks, {cam, cam}, Pipeline::exact, {&out}), std::invalid_argument);
  EXPECT_THROW(cpu::preprocess_batch(*m, chunks, {cam}, Pipeline::exact, {nullptr}), std::invalid_argument);
  EXPECT_THROW(cpu::preprocess_batch(*m, {}, {cam}, Pipeline::exact, {&out}), std::invalid_argument);
}

// The renderer-level path the server's lanes take (Renderer::preprocess_together): 3 CPU
// renderers of one model, pre-processed together at 3 views of 2 sizes, then each renders its
// view. Every image equals a lone renderer's of the same view bit for bit, and the stats say
// the stage 1 was shared (3 views) or not (1).
TEST(BatchPreprocess, RenderersSharingStage1DrawWhatTheyDrawAlone) {
  const auto m = test::cached_scene(test::bundled_scene());
  std::vector<Camera> views = spread(orbit_of(*m, 0.6f, 0.1f), 3);
  views[2] = views[2].rescaled(160, 90);
  RenderOptions o;
  o.pipeline = Pipeline::exact;
  cpu::CpuRenderer a(m, o), b(m, o), c(m, o), alone(m, o);
  a.preprocess_together({&a, &b, &c}, views);
  cpu::CpuRenderer* shared[3] = {&a, &b, &c};
  for (std::size_t k = 0; k < 3; ++k) {
    Image got, want;
    shared[k]->render(views[k], got);
    EXPECT_EQ(shared[k]->last_stats().stage1_views, 3) << "view " << k;
    alone.render(views[k], want);
    EXPECT_EQ(alone.last_stats().stage1_views, 1);
    EXPECT_GT(alone.last_stats().visible, 0u) << "view " << k << " shows nothing: a weak test";
    EXPECT_EQ(got.rgba8, want.rgba8) << "view " << k;
    EXPECT_EQ(got.rgb, want.rgb) << "view " << k;
    EXPECT_EQ(shared[k]->render_list().values, alone.render_list().values) << "view " << k;
  }
  // The mark is used once: the next frame pre-processes alone.
  Image again;
  a.render(views[0], again);
  EXPECT_EQ(a.last_stats().stage1_views, 1);
}

// A batch made for other options or another camera is not used: the frame pre-processes again
// (set_options clears it; a camera that differs in any field does not match).
TEST(BatchPreprocess, RenderersPreprocessAgainForOtherOptionsOrCamera) {
  const auto m = test::cached_scene(test::bundled_scene());
  const std::vector<Camera> views = spread(orbit_of(*m, 0.6f, 0.1f), 2);
  RenderOptions o;
  o.pipeline = Pipeline::exact;
  cpu::CpuRenderer a(m, o), b(m, o), alone(m, o);
  a.preprocess_together({&a, &b}, views);
  RenderOptions vanilla = o;
  vanilla.pipeline = Pipeline::vanilla;
  b.set_options(vanilla);  // the batch was exact's stage 1
  alone.set_options(vanilla);
  Image got, want;
  b.render(views[1], got);
  alone.render(views[1], want);
  EXPECT_EQ(b.last_stats().stage1_views, 1);
  EXPECT_EQ(got.rgba8, want.rgba8);
  Camera moved = views[0];
  moved.t.x += 1e-3f;
  a.render(moved, got);
  EXPECT_EQ(a.last_stats().stage1_views, 1);
  alone.set_options(o);
  alone.render(moved, want);
  EXPECT_EQ(got.rgba8, want.rgba8);
}

// Who may share: one model, one pipeline, one LOD bound; refusals name the renderer.
TEST(BatchPreprocess, RenderersShareOnlyOneSceneAndSettings) {
  const auto m = test::cached_scene(test::bundled_scene());
  const auto other = std::make_shared<const GaussianModel>(*m);  // the same content, another scene
  RenderOptions o;
  o.pipeline = Pipeline::exact;
  RenderOptions coarser = o;
  coarser.lod_error_px = 4.0f;
  RenderOptions vanilla = o;
  vanilla.pipeline = Pipeline::vanilla;
  cpu::CpuRenderer a(m, o), b(m, o), c(other, o), d(m, coarser), e(m, vanilla);
  EXPECT_TRUE(a.shares_stage1_with(b));
  EXPECT_FALSE(a.shares_stage1_with(c)) << "two scenes never share a pass";
  EXPECT_FALSE(a.shares_stage1_with(d));
  EXPECT_FALSE(a.shares_stage1_with(e));
  const std::vector<Camera> two = spread(orbit_of(*m, 0.6f, 0.1f), 2);
  EXPECT_THROW(a.preprocess_together({&a, &c}, two), std::invalid_argument);
  EXPECT_THROW(a.preprocess_together({&b, &a}, two), std::invalid_argument);  // `a` must lead
  EXPECT_THROW(a.preprocess_together({&a, &a}, two), std::invalid_argument);
  EXPECT_THROW(a.preprocess_together({&a, &b}, {two[0]}), std::invalid_argument);
  Image img;
  a.render(two[0], img);  // nothing was marked by the refusals
  EXPECT_EQ(a.last_stats().stage1_views, 1);
}

}  // namespace
}  // namespace catgs
