// Building a scene's level of detail (issue 37; catgs-scene lod, catgs-bench --lod): the tree of
// chunks forward_model/lod.h describes, made offline from any scene.
//
// Steps:
// 1. The leaves: the scene's Gaussians in Morton order (scene/morton.h; a scene that
//    catgs-scene compact wrote already is and is left as it is), or in the input's own order
//    (keep_order: a SuperSplat compressed PLY's chunks, spatially sorted by its writer, then stay
//    the leaf chunks, so a compact LOD file keeps every code the source had:
//    scene/compact_file.h), padded to a multiple of fm::kChunkSize with invisible copies of the
//    last chunk's first Gaussian (opacity logit -kOpacityLogitLimit; a copy, so the chunk's
//    quantization ranges stay its Gaussians'). Leaf node boxes: their means.
// 2. Level l + 1, node j: the `branching` consecutive nodes [b j, b j + b) of level l (all of them
//    chunks), their visible Gaussians grouped into kChunkSize clusters by a median kd split
//    (lod_cluster.h: about m / 256 each, every cluster a box of its own, so no cluster spans a
//    gap between parts of the scene), each cluster merged into one Gaussian (lod_merge.h
//    merge_gaussians; an empty cluster gives padding). Its box: the union of its children's;
//    its parent: set when level l + 2 is built. Levels stop at one node.
//    (Equal runs of the Morton order, the first build, jumped between cells at the curve's
//    seams and merged Gaussians metres apart; at the same number drawn the kd clusters keep
//    more PSNR on the city fly-over: docs/history/level_of_detail.md, "Second round".)
// 3. A node's error (world units): the weighted RMS distance the means of its inputs moved in
//    their merges (MergedGaussian::spread and weight over its clusters, weights as the merge's)
//    plus the largest error of its children, floored at 1e-30 so a merge of singletons still
//    counts as a merge. err_px = error x focal / distance is then how far (pixels, RMS over the
//    node's coverage) detail moves on screen when the node stands for its leaves. RMS over the
//    clusters and not the largest cluster's spread: one sparse cluster (floaters, a lone leaf)
//    would keep its whole chunk at full detail (measured lower at the same number drawn:
//    docs/history/level_of_detail.md, "Second round").
#pragma once

#include <cstddef>
#include <vector>

#include "scene/gaussian_model.h"
#include "scene/load_progress.h"

namespace catgs {

struct LodBuildOptions {
  int branching = 8;  // children per node, 2..64
  // The leaves in the input's order, not Morton-sorted (a compressed PLY source: see step 1).
  bool keep_order = false;
  // Called on the building thread with (input Gaussians processed, in all): the leaves' copies,
  // then each level's merged inputs, in batches; rising, the last call (total, total). What it
  // throws ends the build (a stopping server cancels so).
  LoadProgress progress;
};

struct LodBuildReport {
  std::vector<std::size_t> level_nodes;  // nodes (chunks) of level 0 (leaves), 1, ...
  bool reordered = false;                // the leaves were Morton-sorted (the input was not)
  double seconds = 0;                    // wall time of the build
};

// The LOD model of `scene` (its Gaussians as leaves, then the merged levels; lod filled and
// valid). Throws std::invalid_argument for an empty scene, one that has a LOD already, or a
// branching outside 2..64.
GaussianModel build_lod(const GaussianModel& scene, const LodBuildOptions& options = {},
                        LodBuildReport* report = nullptr);

// How many leaf Gaussians (padding included) a LOD model holds: the Gaussians of its chunks of
// error 0. 0 for a model without LOD.
std::size_t lod_leaf_gaussians(const GaussianModel& model);

// The leaves of a LOD model (its first lod_leaf_gaussians Gaussians, padding included, which
// never draws) without the merged levels and the tree: the scene at full detail. A model without
// LOD is returned as it is.
GaussianModel lod_leaves(GaussianModel model);

}  // namespace catgs
