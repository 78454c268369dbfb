// Level of detail (issue 37; forward_model/lod.h, lod/lod_build.h, lod_merge.h):
// the merge against direct formulas, the eigen solver against its input, the cut property on
// trees built from real scenes, renders of a small real city against the full-detail model on
// both CPU pipelines, and LOD files.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

#include "common/image_io.h"
#include "cpu/cpu_renderer.h"
#include "forward_model/chunk_bounds.h"
#include "renderer/renderer.h"
#include "scene/ply_io.h"
#include "scene/scene_cache.h"
#include "scene_tools/city.h"
#include "lod/lod_build.h"
#include "lod/lod_cluster.h"
#include "lod/lod_merge.h"
#include "scene/morton.h"
#include "small_city.h"
#include "test_data.h"

namespace catgs {
namespace {

namespace fs = std::filesystem;

// The 3x3 covariance of Gaussian i of `m` (fm::covariance_3d), in double.
glm::dmat3 covariance_of(const GaussianModel& m, std::size_t i) {
  const fm::Cov3 c =
      fm::covariance_3d({m.log_scales[3 * i], m.log_scales[3 * i + 1], m.log_scales[3 * i + 2]},
                        {m.rotations[4 * i], m.rotations[4 * i + 1], m.rotations[4 * i + 2], m.rotations[4 * i + 3]});
  return glm::dmat3(c.xx, c.xy, c.xz, c.xy, c.yy, c.yz, c.xz, c.yz, c.zz);
}

double max_abs_diff(const glm::dmat3& a, const glm::dmat3& b) {
  double d = 0.0;
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r) d = std::max(d, std::fabs(a[c][r] - b[c][r]));
  return d;
}

// A model of the Gaussians `pick` of `m`, means moved by `shift[k]`.
GaussianModel subset(const GaussianModel& m, const std::vector<std::size_t>& pick,
                     const std::vector<glm::vec3>& shift) {
  GaussianModel out;
  out.sh_degree = m.sh_degree;
  out.resize(pick.size());
  const std::size_t K3 = static_cast<std::size_t>(m.sh_coeffs()) * 3;
  for (std::size_t k = 0; k < pick.size(); ++k) {
    const std::size_t i = pick[k];
    for (int a = 0; a < 3; ++a) out.means[3 * k + a] = m.means[3 * i + a] + shift[k][a];
    std::copy_n(&m.log_scales[3 * i], 3, &out.log_scales[3 * k]);
    std::copy_n(&m.rotations[4 * i], 4, &out.rotations[4 * k]);
    out.opacity_logits[k] = m.opacity_logits[i];
    std::copy_n(&m.sh[i * K3], K3, &out.sh[k * K3]);
  }
  return out;
}

// The merged Gaussian of `pair` (both of its Gaussians) as a one-Gaussian model.
GaussianModel merged_model(const GaussianModel& pair, MergedGaussian* merged = nullptr) {
  GaussianModel out;
  out.sh_degree = pair.sh_degree;
  out.resize(1);
  const uint32_t index[2] = {0, 1};
  const MergedGaussian g = merge_gaussians(pair, index, 2, out.sh.data());
  for (int a = 0; a < 3; ++a) out.means[a] = g.mean[a], out.log_scales[a] = g.log_scale[a];
  for (int a = 0; a < 4; ++a) out.rotations[a] = g.rotation[a];
  out.opacity_logits[0] = g.opacity_logit;
  if (merged) *merged = g;
  return out;
}

TEST(LodMerge, TwoIdenticalGaussiansMergeIntoWhatThePairCovers) {
  const auto m = test::cached_scene(test::bundled_scene());
  // Three Gaussians of the scene whose pair does not reach the 0.99 clamp.
  std::vector<std::size_t> picked;
  for (std::size_t i = 0; i < m->size() && picked.size() < 3; i += 997) {
    const double alpha = fm::sigmoid(m->opacity_logits[i]);
    if (alpha > 0.3 && alpha < 0.5) picked.push_back(i);
  }
  ASSERT_EQ(picked.size(), 3u);
  for (std::size_t i : picked) {
    const GaussianModel pair = subset(*m, {i, i}, {glm::vec3(0.0f), glm::vec3(0.0f)});
    MergedGaussian g;
    const GaussianModel one = merged_model(pair, &g);
    for (int a = 0; a < 3; ++a) EXPECT_FLOAT_EQ(one.means[a], pair.means[a]) << i;
    const glm::dmat3 want = covariance_of(pair, 0);
    EXPECT_LT(max_abs_diff(covariance_of(one, 0), want), 1e-5 * std::fabs(want[0][0] + want[1][1] + want[2][2])) << i;
    for (std::size_t c = 0; c < pair.sh.size() / 2; ++c) EXPECT_NEAR(one.sh[c], pair.sh[c], 1e-6) << i;
    // Seen from any side, the stacked pair composites to 1 - (1 - alpha g)^2 = 2 alpha g - alpha^2
    // g^2, whose integral over the plane is 2 pi sqrt(det) (2 alpha - alpha^2 / 2) (g^2 is a
    // Gaussian of half the covariance); less the tails below 1/255 the rasterizer skips, 2 pi
    // sqrt(det) / 255 a child. The merged Gaussian covers as much. (The peak the pair reaches,
    // 1 - (1 - alpha)^2, the rule before this one kept, covers alpha^2 / 2 less than the pair.)
    const double alpha = fm::sigmoid(pair.opacity_logits[0]);
    const double covered = 2.0 * alpha - alpha * alpha / 2.0 - 2.0 / 255.0;
    // The fit's grid widens each child by a quarter of its step squared (lod_fit.h), which lowers
    // the overlap term, most in a projection thin against the grid: up to 0.02 over (0.012 seen).
    EXPECT_NEAR(fm::sigmoid(one.opacity_logits[0]), covered + 0.01, 0.01) << i << " alpha " << alpha;
    EXPECT_GT(std::fabs(fm::sigmoid(one.opacity_logits[0]) - (1.0 - (1.0 - alpha) * (1.0 - alpha))), 0.015) << i;
    EXPECT_LT(g.spread, 1e-6f) << i;  // the means coincide (double rounding aside)
  }
}

TEST(LodMerge, TwoGaussiansApartMatchTheMixtureMoments) {
  const auto m = test::cached_scene(test::bundled_scene());
  const GaussianModel pair = subset(*m, {10, 20000}, {glm::vec3(0.0f), glm::vec3(0.3f, -0.1f, 0.2f)});
  const GaussianModel one = merged_model(pair);
  // The mixture's moments in the second-moment form, E[x x^T] - mu mu^T, with the weights
  // opacity x the product of the two largest std devs.
  double w[2], w_sum = 0.0;
  for (int k = 0; k < 2; ++k) {
    glm::dvec3 s(std::exp(pair.log_scales[3 * k]), std::exp(pair.log_scales[3 * k + 1]),
                 std::exp(pair.log_scales[3 * k + 2]));
    const double smallest = std::min({s.x, s.y, s.z});
    w[k] = fm::sigmoid(pair.opacity_logits[k]) * (s.x * s.y * s.z / smallest);
    w_sum += w[k];
  }
  glm::dvec3 mu(0.0);
  glm::dmat3 second(0.0);
  for (int k = 0; k < 2; ++k) {
    const glm::dvec3 x(pair.means[3 * k], pair.means[3 * k + 1], pair.means[3 * k + 2]);
    mu += w[k] / w_sum * x;
    second += w[k] / w_sum * (covariance_of(pair, k) + glm::outerProduct(x, x));
  }
  const glm::dmat3 cov = second - glm::outerProduct(mu, mu);
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(one.means[a], mu[a], 1e-5);
  EXPECT_LT(max_abs_diff(covariance_of(one, 0), cov), 1e-5 * (cov[0][0] + cov[1][1] + cov[2][2]));
}

// Two round Gaussians apart, one twice as wide: the merge's colour is their mix by what each
// covers, sigma_i^2 (alpha_i - 1/255) (a round Gaussian covers 2 pi sigma^2 (alpha - 1/255) above
// the rasterizer's 1/255 from every side), not by opacity alone, and its opacity spreads what they
// cover over the merged Gaussian's area.
TEST(LodMerge, TwoGaussiansApartMixTheirColoursByWhatEachCovers) {
  GaussianModel pair;
  pair.sh_degree = 0;
  pair.resize(2);
  const double sigma[2] = {0.1, 0.05}, alpha[2] = {0.3, 0.8};
  for (int k = 0; k < 2; ++k) {
    pair.means[3 * k] = k == 0 ? 0.0f : 0.6f;
    for (int a = 0; a < 3; ++a) pair.log_scales[3 * k + a] = static_cast<float>(std::log(sigma[k]));
    pair.rotations[4 * k] = 1.0f;
    pair.opacity_logits[k] = static_cast<float>(std::log(alpha[k] / (1.0 - alpha[k])));
    for (int c = 0; c < 3; ++c) pair.sh[3 * k + c] = k == 0 ? 1.0f : -1.0f;
  }
  const GaussianModel one = merged_model(pair);
  const double w0 = sigma[0] * sigma[0] * (alpha[0] - 1.0 / 255), w1 = sigma[1] * sigma[1] * (alpha[1] - 1.0 / 255);
  const double by_cover = (w0 - w1) / (w0 + w1), by_alpha = (alpha[0] - alpha[1]) / (alpha[0] + alpha[1]);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(one.sh[c], by_cover, 0.05) << "the coverage mix " << by_cover << ", opacity's " << by_alpha;
    EXPECT_GT(std::fabs(one.sh[c] - by_alpha), 0.3);
  }
  // Opacity: what both cover (they never overlap), over the merged Gaussian's projected area,
  // averaged over the seven directions of lod_fit.h, as their sums. Round children cover the same
  // from every side; the merged Gaussian's area is 2 pi sqrt(det) of its projection.
  const glm::dmat3 cov = covariance_of(one, 0);
  glm::dvec3 lambda;
  glm::dmat3 axes;
  symmetric_eigen3(cov, lambda, axes);
  const double k = 1.0 / std::sqrt(3.0);
  const glm::dvec3 dirs[7] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {k, k, k}, {-k, k, k}, {k, -k, k}, {k, k, -k}};
  double area = 0.0;
  for (const glm::dvec3& local : dirs) {
    // det of the projection of cov along unit d = lambda1 lambda2 lambda3 (d^T cov^-1 d).
    const glm::dvec3 d = axes * local;
    area += std::sqrt(lambda.x * lambda.y * lambda.z * glm::dot(d, glm::inverse(cov) * d));
  }
  const double want = 7.0 * (w0 + w1) / area;
  EXPECT_NEAR(fm::sigmoid(one.opacity_logits[0]), want, 0.1 * want);
}

// A merged Gaussian drawn with its coverage kept (fm::drawn_opacity): summed over the pixels, its
// alpha is what the Gaussian covers without the low-pass, as an 8x supersampled drawing sums it,
// at any size on screen; a leaf, drawn as the reference 3DGS draws it, covers more the smaller it
// is (the low-pass widens it, its peak stays).
TEST(LodDraw, MergedGaussianCoversWhatItIsAtAnySize) {
  const float opacity = 0.6f, fx = 1000.0f;
  const glm::mat3 identity(1.0f);
  for (float sigma_px : {0.3f, 0.6f, 1.2f, 3.0f}) {
    const float z = 10.0f, sigma = sigma_px * z / fx;
    const fm::Cov3 cov3 =
        fm::covariance_3d(glm::vec3(std::log(sigma), std::log(1.5f * sigma), std::log(sigma)), glm::vec4(1, 0, 0, 0));
    const glm::vec3 cov2 = fm::covariance_2d(cov3, identity, glm::vec3(0.0f, 0.0f, z), fx, fx, glm::vec2(1.0f));
    glm::vec3 conic, conic_own;
    ASSERT_TRUE(fm::conic_from_cov2d(cov2, &conic));
    ASSERT_TRUE(fm::conic_from_cov2d(cov2 - glm::vec3(fm::kLowPass, 0.0f, fm::kLowPass), &conic_own));
    const float ext = 12.0f * sigma_px + 6.0f;
    double reference = 0.0, merged = 0.0, leaf = 0.0;
    const float drawn = fm::drawn_opacity(opacity, cov2, true);
    EXPECT_EQ(fm::drawn_opacity(opacity, cov2, false), opacity);
    for (float y = -ext; y <= ext; y += 0.125f)
      for (float x = -ext; x <= ext; x += 0.125f) reference += opacity * std::exp(fm::gaussian_power(conic_own, x, y));
    reference /= 64.0;
    for (float y = -ext; y <= ext; y += 1.0f)
      for (float x = -ext; x <= ext; x += 1.0f) {
        merged += drawn * std::exp(fm::gaussian_power(conic, x, y));
        leaf += opacity * std::exp(fm::gaussian_power(conic, x, y));
      }
    EXPECT_NEAR(merged, reference, 0.01 * reference) << sigma_px << " px";
    if (sigma_px <= 1.2f) {
      EXPECT_GT(leaf, 1.1 * reference) << sigma_px << " px";
    }
  }
}

// fm::drawn_qmax bounds the drawn Gaussian's q_max from above without a second logarithm: never
// below 2 ln(255 opacity scale) (else a tile the Gaussian blends in would go unlisted), within
// 0.3 of it while the drawn peak keeps a third of the undrawn one (else the bound lists needless
// tiles), and exact for a leaf.
TEST(LodDraw, DrawnQmaxBoundsTheDrawnPeaksFromAbove) {
  for (float opacity : {0.01f, 0.1f, 0.5f, 0.99f}) {
    const float q_max = fm::opacity_aware_qmax(opacity);
    EXPECT_EQ(fm::drawn_qmax(q_max, 1.0f), q_max);
    for (float scale = 1e-4f; scale < 1.0f; scale *= 1.05f) {
      const double exact = 2.0 * std::log(255.0 * opacity * scale);
      const float bound = fm::drawn_qmax(q_max, scale);
      EXPECT_GE(bound, exact - 1e-5) << opacity << " x " << scale;
      if (scale >= 1.0f / 3.0f) EXPECT_LE(bound, exact + 0.3) << opacity << " x " << scale;
    }
  }
}

TEST(LodMerge, EigenSolverReconstructsItsInput) {
  std::mt19937 rng(37);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  const auto m = test::cached_scene(test::bundled_scene());
  for (int t = 0; t < 300; ++t) {
    glm::dmat3 a;
    if (t < 200) {
      for (int c = 0; c < 3; ++c)
        for (int r = 0; r <= c; ++r) a[c][r] = a[r][c] = u(rng);
    } else {
      a = covariance_of(*m, static_cast<std::size_t>(t) * 500);  // real, often very flat
    }
    if (t == 0) a = glm::dmat3(1.0);  // already diagonal, repeated eigenvalues
    glm::dvec3 values;
    glm::dmat3 v;
    symmetric_eigen3(a, values, v);
    const double scale = std::max({std::fabs(values[0]), std::fabs(values[1]), std::fabs(values[2]), 1e-30});
    glm::dmat3 d(0.0);
    for (int k = 0; k < 3; ++k) d[k][k] = values[k];
    EXPECT_LT(max_abs_diff(v * d * glm::transpose(v), a), 1e-12 * scale) << t;
    EXPECT_LT(max_abs_diff(glm::transpose(v) * v, glm::dmat3(1.0)), 1e-12) << t;
    EXPECT_NEAR(glm::determinant(v), 1.0, 1e-12) << t;
    EXPECT_GE(values[0], values[1]);
    EXPECT_GE(values[1], values[2]);
    // The quaternion turns back into the same rotation through the forward model.
    const glm::mat3 r = fm::quat_to_mat(quaternion_of(v));
    EXPECT_LT(max_abs_diff(glm::dmat3(r), v), 1e-6) << t;
  }
}

// --- Clusters: a median kd split of a node's Gaussians ------------------------------------------

// A 16 x 16 x 8 lattice (spacing 1, shuffled, offset) has one right answer for 256 equal
// clusters that are as small as can be: its 2 x 2 x 2 blocks (a cluster of 8 lattice points
// any wider spans a gap of at least one spacing).
TEST(LodCluster, ALatticeSplitsIntoItsBlocks) {
  std::vector<float> means;
  for (int x = 0; x < 16; ++x)
    for (int y = 0; y < 16; ++y)
      for (int z = 0; z < 8; ++z)
        for (float v : {x + 3.0f, y + 5.0f, z + 1.0f}) means.push_back(v);
  std::vector<uint32_t> items(means.size() / 3);
  std::iota(items.begin(), items.end(), 0u);
  std::shuffle(items.begin(), items.end(), std::mt19937(37));
  const std::vector<std::size_t> bounds = kd_clusters(means.data(), items, 256);
  ASSERT_EQ(bounds.size(), 257u);
  std::vector<int> seen(items.size());
  for (std::size_t r = 0; r < 256; ++r) {
    ASSERT_EQ(bounds[r + 1] - bounds[r], 8u) << "cluster " << r;
    for (int a = 0; a < 3; ++a) {
      float lo = INFINITY, hi = -INFINITY;
      for (std::size_t k = bounds[r]; k < bounds[r + 1]; ++k) {
        lo = std::min(lo, means[3 * items[k] + a]);
        hi = std::max(hi, means[3 * items[k] + a]);
      }
      EXPECT_EQ(hi - lo, 1.0f) << "cluster " << r << " axis " << a;  // one block, not two
    }
    for (std::size_t k = bounds[r]; k < bounds[r + 1]; ++k) ++seen[items[k]];
  }
  for (std::size_t i = 0; i < seen.size(); ++i) ASSERT_EQ(seen[i], 1) << "item " << i;
}

// Random counts: every item once, sizes floor or ceil of the mean, and fewer items than
// clusters leave the rest empty.
TEST(LodCluster, SizesAreEvenAndEveryItemIsKept) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-5.0f, 5.0f);
  for (std::size_t n : {0ul, 1ul, 100ul, 255ul, 256ul, 257ul, 1000ul, 2048ul}) {
    std::vector<float> means(3 * n);
    for (float& v : means) v = u(rng);
    std::vector<uint32_t> items(n);
    std::iota(items.begin(), items.end(), 0u);
    const std::vector<std::size_t> bounds = kd_clusters(means.data(), items, 256);
    ASSERT_EQ(bounds.front(), 0u);
    ASSERT_EQ(bounds.back(), n);
    for (std::size_t r = 0; r < 256; ++r) {
      ASSERT_LE(bounds[r], bounds[r + 1]) << n;
      EXPECT_GE(bounds[r + 1] - bounds[r], n / 256) << n << " cluster " << r;
      EXPECT_LE(bounds[r + 1] - bounds[r], (n + 255) / 256) << n << " cluster " << r;
    }
    std::vector<uint32_t> sorted = items;
    std::sort(sorted.begin(), sorted.end());
    for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(sorted[i], i) << n;
  }
  std::vector<uint32_t> none;
  EXPECT_THROW(kd_clusters(nullptr, none, 0), std::invalid_argument);
}

// Every leaf chunk has exactly one drawn node among itself and its ancestors.
void expect_cut(const std::vector<fm::LodNode>& lod, const fm::View& v, float tau, const std::string& what) {
  std::size_t leaves = 0;
  while (leaves < lod.size() && lod[leaves].error == 0.0f) ++leaves;
  std::vector<char> drawn(lod.size());
  for (std::size_t c = 0; c < lod.size(); ++c) drawn[c] = fm::lod_chunk_drawn(lod.data(), c, v, tau);
  for (std::size_t c = 0; c < leaves; ++c) {
    int on_path = 0;
    for (uint32_t n = static_cast<uint32_t>(c); n != fm::kLodNoParent; n = lod[n].parent) on_path += drawn[n];
    ASSERT_EQ(on_path, 1) << what << ": leaf chunk " << c << " at tau " << tau;
  }
  if (tau == 0.0f)
    for (std::size_t c = 0; c < lod.size(); ++c) ASSERT_EQ(drawn[c] != 0, c < leaves) << what << ": chunk " << c;
}

TEST(LodTree, EveryViewDrawsACutThroughTheTree) {
  const auto m = test::cached_scene(test::bundled_scene());
  LodBuildReport report;
  const GaussianModel lod = build_lod(*m, {}, &report);
  lod.validate();
  ASSERT_GE(report.level_nodes.size(), 3u);
  EXPECT_EQ(report.level_nodes.front(), fm::chunk_count(m->size()));
  EXPECT_EQ(report.level_nodes.back(), 1u);
  EXPECT_EQ(lod_leaf_gaussians(lod), report.level_nodes.front() * fm::kChunkSize);
  const Bounds b = m->bounds();
  const float size = glm::length(b.extent());
  std::mt19937 rng(3737);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::size_t above_leaves = 0;
  for (int t = 0; t < 60; ++t) {
    // Inside the scene's box, near it and far from it, looking anywhere.
    const float reach = t < 20 ? 0.5f : t < 40 ? 2.0f : 40.0f;
    const glm::vec3 at = b.center() + reach * size * glm::vec3(u(rng), u(rng), u(rng));
    const glm::quat q = glm::normalize(glm::quat(u(rng), u(rng), u(rng), u(rng)));
    const fm::View v = fm::view_of(Camera::from_pose(at, q, 60.0f, 640, 360));
    for (float tau : {0.0f, 0.25f, 1.0f, 4.0f, 64.0f, 1e9f}) {
      expect_cut(lod.lod, v, tau, "view " + std::to_string(t));
      if (tau > 0.0f)
        for (std::size_t c = lod_leaf_gaussians(lod) / fm::kChunkSize; c < lod.lod.size(); ++c)
          above_leaves += fm::lod_chunk_drawn(lod.lod.data(), c, v, tau) ? 1 : 0;
    }
  }
  EXPECT_GT(above_leaves, 0u) << "no view drew a merged node";
}

TEST(LodTree, LeavesAreTheSceneInMortonOrderAndBoxesNest) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const auto m = test::cached_scene(path);
  const GaussianModel lod = build_lod(*m);
  const GaussianModel sorted = permuted(*m, morton_order(*m));
  const std::size_t n = m->size();
  EXPECT_EQ(std::memcmp(lod.means.data(), sorted.means.data(), 3 * n * 4), 0);
  EXPECT_EQ(std::memcmp(lod.sh.data(), sorted.sh.data(), sorted.sh.size() * 4), 0);
  EXPECT_EQ(std::memcmp(lod.opacity_logits.data(), sorted.opacity_logits.data(), n * 4), 0);
  for (std::size_t i = n; i < lod_leaf_gaussians(lod); ++i)
    EXPECT_LT(fm::sigmoid(lod.opacity_logits[i]), fm::kMinAlpha) << "padding " << i;
  // Every leaf Gaussian's mean lies in the box of every node above it.
  for (std::size_t i = 0; i < n; i += 7)
    for (uint32_t c = static_cast<uint32_t>(i / fm::kChunkSize); c != fm::kLodNoParent; c = lod.lod[c].parent)
      for (int a = 0; a < 3; ++a) {
        ASSERT_LE(lod.lod[c].lo[a], lod.means[3 * i + a]) << i << " node " << c;
        ASSERT_GE(lod.lod[c].hi[a], lod.means[3 * i + a]) << i << " node " << c;
      }
  // A Morton-sorted scene is not sorted again.
  LodBuildReport report;
  (void)build_lod(sorted, {}, &report);
  EXPECT_FALSE(report.reordered);
}

TEST(LodTree, ValidateRefusesBrokenTrees) {
  const auto m = test::cached_scene(test::bundled_scene());
  const GaussianModel good = build_lod(*m);
  struct Case {
    const char* name;
    std::function<void(GaussianModel&)> damage;
    const char* says;
  };
  const std::size_t top = good.lod.size() - 1, leaf = 5;
  const std::vector<Case> cases = {
      {"a node short", [](GaussianModel& g) { g.lod.pop_back(); }, "nodes for"},
      {"a parent below", [&](GaussianModel& g) { g.lod[top - 1].parent = 0; }, "not a higher chunk"},
      {"an error above its parent's",
       [&](GaussianModel& g) { g.lod[g.lod[leaf].parent].error = 2.0f * g.lod[top].error + 1.0f; },
       "error above its parent's"},
      {"a box outside its parent's", [&](GaussianModel& g) { g.lod[leaf].hi[0] = g.lod[top].hi[0] + 1.0f; },
       "box not inside"},
      {"a NaN error", [&](GaussianModel& g) { g.lod[top].error = NAN; }, "not finite"},
  };
  for (const Case& c : cases) {
    GaussianModel bad = good;
    c.damage(bad);
    try {
      bad.validate();
      ADD_FAILURE() << c.name << ": accepted";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(c.says), std::string::npos) << c.name << ": " << e.what();
    }
  }
}

// --- Renders: a small city of a real scene, the full model against its LOD --------------------

using test::small_flowers_city;

// Renders `views` of `model` with `pipeline` at `tau`, frame k posed at k / 120 s.
std::vector<Image> render(std::shared_ptr<const GaussianModel> model, Pipeline pipeline, float tau,
                          const std::vector<Camera>& views, std::vector<std::size_t>* visible = nullptr) {
  RenderOptions o;
  o.pipeline = pipeline;
  o.lod_error_px = tau;
  auto r = make_renderer("cpu", std::move(model), o);
  std::vector<Image> out(views.size());
  for (std::size_t k = 0; k < views.size(); ++k) {
    r->render_at(views[k], static_cast<double>(k) / 120.0, out[k]);
    if (visible) visible->push_back(r->last_stats().visible);
  }
  return out;
}

TEST(LodRender, FullDetailIsBitIdenticalAndTheDefaultKeeps35dB) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const test::SmallCity& c = small_flowers_city();
  const float tau = RenderOptions{}.lod_error_px;
  ASSERT_GT(tau, 0.0f);
  for (Pipeline p : {Pipeline::exact, Pipeline::catgs}) {
    std::vector<std::size_t> full_visible, lod_visible;
    const auto full = render(c.full, p, tau, c.views, &full_visible);  // no LOD: tau ignored
    const auto zero = render(c.lod, p, 0.0f, c.views);
    const auto lod = render(c.lod, p, tau, c.views, &lod_visible);
    bool fewer = false;
    for (std::size_t k = 0; k < c.views.size(); ++k) {
      EXPECT_EQ(zero[k].rgba8, full[k].rgba8) << pipeline_name(p) << " view " << k;
      EXPECT_EQ(zero[k].rgb, full[k].rgb) << pipeline_name(p) << " view " << k;
      const double psnr = psnr_rgba8(lod[k], full[k]);
      EXPECT_GE(psnr, 35.0) << pipeline_name(p) << " view " << k;
      EXPECT_LE(lod_visible[k], full_visible[k]) << pipeline_name(p) << " view " << k;
      fewer = fewer || lod_visible[k] < full_visible[k];
      std::printf("%s view %zu: PSNR %.2f dB, visible %zu of %zu\n", pipeline_name(p), k, psnr, lod_visible[k],
                  full_visible[k]);
    }
    EXPECT_TRUE(fewer) << pipeline_name(p) << ": no view drew fewer Gaussians with LOD";
  }
}

// --- LOD files ----------------------------------------------------------------------------------

TEST(LodFile, WritesWhatItReadsAndRefusesBadFiles) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const std::string dir = test::temp_dir();
  const std::string scene = dir + "/flowers.ply", out = dir + "/flowers.catgs-lod";
  fs::copy_file(path, scene);
  const GaussianModel lod = build_lod(load_scene(scene));
  write_scene_cache(lod, scene, out);
  // Read back, it is the model a fresh build makes (the build is deterministic).
  const GaussianModel again = load_lod_file(out, scene);
  const GaussianModel rebuilt = build_lod(load_scene(scene));
  ASSERT_EQ(again.size(), rebuilt.size());
  ASSERT_EQ(again.lod.size(), rebuilt.lod.size());
  EXPECT_EQ(std::memcmp(again.lod.data(), rebuilt.lod.data(), again.lod.size() * sizeof(fm::LodNode)), 0);
  test::expect_same_gaussians(again, rebuilt);
  auto refused = [&](const std::string& file, const std::string& says) {
    test::expect_refused<SceneCacheRejected>([&] { (void)load_lod_file(file, scene); }, file, says);
  };
  const std::string cut = dir + "/cut.catgs-lod";
  fs::copy_file(out, cut);
  fs::resize_file(cut, fs::file_size(out) - 4096);
  refused(cut, "truncated");
  const std::string foreign = dir + "/foreign.catgs-lod";
  std::ofstream(foreign) << std::string(8192, 'x');
  refused(foreign, "not a scene cache");
  const std::string plain = dir + "/plain.catgs-cache";
  write_scene_cache(load_scene(scene), scene, plain);
  refused(plain, "without a level of detail");
}

}  // namespace
}  // namespace catgs
