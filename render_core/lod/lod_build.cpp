// The LOD tree's build (lod_build.h): leaves in Morton order, then merged levels, each level's
// nodes in parallel.
#include "lod/lod_build.h"

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <numeric>
#include <stdexcept>
#include <string>

#include "forward_model/chunk_bounds.h"
#include "lod/lod_cluster.h"
#include "lod/lod_merge.h"
#include "scene/morton.h"
#include "base/parallel_for.h"

namespace catgs {

namespace {

constexpr std::size_t kChunk = fm::kChunkSize;
constexpr float kMinMergeError = 1e-30f;  // a merged node's error is never 0 (0 marks a leaf)

// Gaussian g of `out` as padding sitting at `at` (lod_build.h step 1).
void write_padding(GaussianModel& out, std::size_t g, const float* at) {
  std::copy_n(at, 3, &out.means[3 * g]);
  std::fill_n(&out.log_scales[3 * g], 3, kLodPadLogScale);
  const float identity[4] = {1.0f, 0.0f, 0.0f, 0.0f};
  std::copy_n(identity, 4, &out.rotations[4 * g]);
  out.opacity_logits[g] = -kOpacityLogitLimit;
  const std::size_t K3 = static_cast<std::size_t>(out.sh_coeffs()) * 3;
  std::fill_n(&out.sh[g * K3], K3, 0.0f);
}

// Copies Gaussian i of `from` to Gaussian g of `to`.
void copy_gaussian(const GaussianModel& from, std::size_t i, GaussianModel& to, std::size_t g) {
  std::copy_n(&from.means[3 * i], 3, &to.means[3 * g]);
  std::copy_n(&from.log_scales[3 * i], 3, &to.log_scales[3 * g]);
  std::copy_n(&from.rotations[4 * i], 4, &to.rotations[4 * g]);
  to.opacity_logits[g] = from.opacity_logits[i];
  const std::size_t K3 = static_cast<std::size_t>(from.sh_coeffs()) * 3;
  std::copy_n(&from.sh[i * K3], K3, &to.sh[g * K3]);
}

// The leaves (step 1): chunk c of `out` from the Gaussians order[c * 256 ...] of the scene.
void build_leaf(const GaussianModel& scene, const std::vector<uint32_t>& order, std::size_t c, GaussianModel& out) {
  fm::LodNode node{{INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}, 0.0f, fm::kLodNoParent};
  const std::size_t n = scene.size();
  for (std::size_t g = c * kChunk; g < (c + 1) * kChunk; ++g) {
    if (g >= n) {  // a copy of the chunk's first, never drawn: the chunk's ranges stay its Gaussians'
      copy_gaussian(scene, order[c * kChunk], out, g);
      out.opacity_logits[g] = -kOpacityLogitLimit;
      continue;
    }
    copy_gaussian(scene, order[g], out, g);
    for (int a = 0; a < 3; ++a) {
      node.lo[a] = std::min(node.lo[a], out.means[3 * g + a]);
      node.hi[a] = std::max(node.hi[a], out.means[3 * g + a]);
    }
  }
  out.lod[c] = node;
}

// Node j of a merged level (step 2): its chunk `chunk`, its children the chunks
// [child_begin, child_end) of the level below.
void build_node(GaussianModel& out, std::size_t chunk, std::size_t child_begin, std::size_t child_end) {
  std::vector<uint32_t> visible;
  visible.reserve((child_end - child_begin) * kChunk);
  fm::LodNode node{{INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}, 0.0f, fm::kLodNoParent};
  float child_error = 0.0f;
  for (std::size_t k = child_begin; k < child_end; ++k) {
    for (std::size_t g = k * kChunk; g < (k + 1) * kChunk; ++g)
      if (!is_lod_padding(out.opacity_logits[g])) visible.push_back(static_cast<uint32_t>(g));
    fm::LodNode& child = out.lod[k];
    child.parent = static_cast<uint32_t>(chunk);
    child_error = std::max(child_error, child.error);
    for (int a = 0; a < 3; ++a) {
      node.lo[a] = std::min(node.lo[a], child.lo[a]);
      node.hi[a] = std::max(node.hi[a], child.hi[a]);
    }
  }
  const std::size_t K3 = static_cast<std::size_t>(out.sh_coeffs()) * 3;
  const std::vector<std::size_t> runs = kd_clusters(out.means.data(), visible, kChunk);
  double spread_sq = 0.0, weight = 0.0;  // the node's weighted mean square spread
  const std::size_t first = chunk * kChunk;
  std::size_t anchor = child_begin * kChunk;  // where padding sits (below)
  bool anchored = false;
  for (std::size_t r = 0; r < kChunk; ++r) {
    const std::size_t lo = runs[r], hi = runs[r + 1], g = first + r;
    if (lo == hi) continue;  // padding, written below once the chunk's first mean is known
    const MergedGaussian merged = merge_gaussians(out, visible.data() + lo, static_cast<int>(hi - lo), &out.sh[g * K3]);
    for (int a = 0; a < 3; ++a) {
      out.means[3 * g + a] = merged.mean[a];
      out.log_scales[3 * g + a] = merged.log_scale[a];
    }
    for (int a = 0; a < 4; ++a) out.rotations[4 * g + a] = merged.rotation[a];
    out.opacity_logits[g] = merged.opacity_logit;
    spread_sq += merged.weight * static_cast<double>(merged.spread) * merged.spread;
    weight += merged.weight;
    if (!anchored) anchor = g, anchored = true;
  }
  // Padding sits on the chunk's first merged mean (or its first child's first mean when nothing
  // was visible), so it widens no chunk bound.
  for (std::size_t r = 0; r < kChunk; ++r)
    if (runs[r] == runs[r + 1]) write_padding(out, first + r, &out.means[3 * anchor]);
  const double spread = weight > 0.0 ? std::sqrt(spread_sq / weight) : 0.0;
  node.error = std::max(child_error + static_cast<float>(spread), kMinMergeError);
  out.lod[chunk] = node;
}

}  // namespace

GaussianModel build_lod(const GaussianModel& scene, const LodBuildOptions& options, LodBuildReport* report) {
  const auto start = std::chrono::steady_clock::now();
  if (scene.size() == 0) throw std::invalid_argument("build_lod: an empty scene");
  if (!scene.lod.empty()) throw std::invalid_argument("build_lod: the scene has a level of detail already");
  const std::size_t b = static_cast<std::size_t>(options.branching);
  if (options.branching < 2 || options.branching > 64)
    throw std::invalid_argument("build_lod: branching " + std::to_string(options.branching) + " outside 2..64");

  std::vector<std::size_t> nodes{fm::chunk_count(scene.size())}, first{0};
  while (nodes.back() > 1) {
    first.push_back(first.back() + nodes.back());
    nodes.push_back((nodes.back() + b - 1) / b);
  }
  const std::size_t chunks = first.back() + nodes.back();
  if (chunks * kChunk > UINT32_MAX) throw std::invalid_argument("build_lod: over 2^32 Gaussians with the levels");

  GaussianModel out;
  out.name = scene.name;
  out.sh_degree = scene.sh_degree;
  out.resize(chunks * kChunk);
  out.lod.resize(chunks);

  std::vector<uint32_t> order;
  if (options.keep_order) {
    order.resize(scene.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<uint32_t>(i);
  } else {
    order = morton_order(scene);
  }
  bool reordered = false;
  for (std::size_t i = 0; i < order.size() && !reordered; ++i) reordered = order[i] != i;
  // Progress counts input Gaussians: the leaves' copies, then every level's merged inputs (its
  // children's chunks); reported from this thread between batches of a level's nodes.
  uint64_t done = 0, total = 0;
  for (std::size_t l = 0; l < nodes.size(); ++l) total += (l == 0 ? nodes[0] : nodes[l - 1]) * kChunk;
  const auto tell = [&](uint64_t add) {
    done += add;
    if (options.progress) options.progress(std::min(done, total), total);
  };
  parallel_for(nodes[0], 16, [&](std::size_t c) { build_leaf(scene, order, c, out); });
  std::vector<uint32_t>().swap(order);
  tell(nodes[0] * kChunk);

  for (std::size_t l = 1; l < nodes.size(); ++l) {
    constexpr std::size_t kBatches = 16;  // progress reports a level
    const std::size_t batch = (nodes[l] + kBatches - 1) / kBatches;
    for (std::size_t lo = 0; lo < nodes[l]; lo += batch) {
      const std::size_t hi = std::min(nodes[l], lo + batch);
      parallel_for(hi - lo, 1, [&](std::size_t i) {
        const std::size_t j = lo + i;
        const std::size_t begin = first[l - 1] + b * j, end = first[l - 1] + std::min(b * j + b, nodes[l - 1]);
        build_node(out, first[l] + j, begin, end);
      });
      tell((std::min(b * hi, nodes[l - 1]) - b * lo) * kChunk);
    }
  }

  if (report) {
    report->level_nodes = nodes;
    report->reordered = reordered;
    report->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return out;
}

std::size_t lod_leaf_gaussians(const GaussianModel& model) {
  std::size_t leaves = 0;
  while (leaves < model.lod.size() && model.lod[leaves].error == 0.0f) ++leaves;
  return leaves * kChunk;
}

GaussianModel lod_leaves(GaussianModel model) {
  if (model.lod.empty()) return model;
  const std::size_t n = lod_leaf_gaussians(model);
  const std::size_t K3 = static_cast<std::size_t>(model.sh_coeffs()) * 3;
  model.means.resize(3 * n);
  model.log_scales.resize(3 * n);
  model.rotations.resize(4 * n);
  model.opacity_logits.resize(n);
  model.sh.resize(K3 * n);
  model.lod.clear();
  model.codes.reset();  // the arrays are shorter: the codes no longer match
  return model;
}

}  // namespace catgs
