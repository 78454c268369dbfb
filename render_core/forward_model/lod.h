// Level of detail (issue 37): a tree of chunks whose upper levels are merged Gaussians, cut per
// view by screen-space error inside the chunk culling both cores already do, so a far part of a
// city costs a few merged chunks instead of every Gaussian it holds (Hierarchical 3DGS, Kerbl et
// al., SIGGRAPH 2024, sec. 4: a hierarchy of merged Gaussians cut by projected size).
//
// Layout of a scene with LOD (lod/lod_build.h writes it): the original Gaussians
// (the leaves) first, padded with invisible Gaussians to a multiple of kChunkSize, then the
// merged Gaussians of level 1, level 2, ... up to a level of one node; every node is exactly one
// chunk of kChunkSize Gaussians (its last ones may be padding). GaussianModel::lod holds one
// LodNode per chunk (empty: no LOD, every chunk is drawn).
//
// The cut, per chunk and stateless (no per-frame host work, no kernel of its own): the projected
// error of node c seen from the camera centre e is
//   err_px(c) = error(c) * max(fx, fy) / dist(e, box(c))   (infinite when e lies in the box),
// and chunk c is drawn iff (leaf(c) or err_px(c) <= tau) and (root(c) or err_px(parent) > tau).
// Errors never decrease upwards and a parent's box contains its children's, so err_px never
// increases down a root-to-leaf path (float subtraction, products and sqrt are monotone): exactly
// one node of every such path is drawn, the highest whose err_px is <= tau. tau <= 0 draws the
// leaves only, the scene as it was before LOD, bit for bit.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "forward_model/forward_model.h"

namespace catgs::fm {

inline constexpr uint32_t kLodNoParent = 0xffffffffu;  // LodNode::parent of a root

// The rule that made a LOD's merged levels and that draws them (lod/lod_merge.h, drawn_opacity
// below), recorded in a compact LOD file (scene/compact_file.h): a keyed LOD file of another rule
// is rebuilt. 1 (recorded as 0): optical depth kept, drawn as the leaves; 2: fitted to the
// children's drawing, coverage kept under the low-pass.
inline constexpr uint32_t kLodMergeRule = 2;

// One chunk's node, 32 bytes (two float4 loads on the GPU).
// - lo, hi: the box of the means of every LEAF Gaussian below the node (itself for a leaf), world
//   units; a parent's box contains its children's.
// - error: world units, how far drawing this node instead of its leaves can be off (0 for a leaf,
//   > 0 above; never below a child's). lod_build.h says how it is measured.
// - parent: the parent's chunk index (a higher chunk), kLodNoParent for a root.
struct alignas(16) LodNode {
  float lo[3];
  float hi[3];
  float error;
  uint32_t parent;
};
static_assert(sizeof(LodNode) == 32, "two float4");

// A product and a sum that never fuse into an FMA, so the CPU and every CUDA kernel (some are
// built with contraction on, cuda/CMakeLists.txt) round the cut's arithmetic alike and draw the
// same chunks.
CATGS_HD float lod_mul(float a, float b) {
#ifdef __CUDA_ARCH__
  return __fmul_rn(a, b);
#else
  return a * b;
#endif
}
CATGS_HD float lod_add(float a, float b) {
#ifdef __CUDA_ARCH__
  return __fadd_rn(a, b);
#else
  return a + b;
#endif
}

// The camera centre of view v in world units: -R^T t (glm: R[c] is column c, so (R^T t)_c is
// column c dotted with t).
CATGS_HD glm::vec3 lod_eye(const View& v) {
  glm::vec3 e;
  for (int c = 0; c < 3; ++c)
    e[c] = -lod_add(lod_add(lod_mul(v.R[c][0], v.t[0]), lod_mul(v.R[c][1], v.t[1])), lod_mul(v.R[c][2], v.t[2]));
  return e;
}

// err_px of node n seen from `eye` with focal length `focal` (pixels): 0 for a leaf, infinite
// inside the box (and where the distance underflows to 0).
CATGS_HD float lod_error_px(const LodNode& n, glm::vec3 eye, float focal) {
  if (n.error == 0.0f) return 0.0f;
  float d2 = 0.0f;
  for (int a = 0; a < 3; ++a) {
    const float gap = fmaxf(fmaxf(n.lo[a] - eye[a], eye[a] - n.hi[a]), 0.0f);
    d2 = lod_add(d2, lod_mul(gap, gap));
  }
  const float d = sqrtf(d2);
  return d > 0.0f ? lod_mul(n.error, focal) / d : INFINITY;
}

// Is chunk c a merged level's (error > 0)? Its Gaussians are drawn with their coverage kept
// (drawn_opacity below). `nodes`: the scene's LodNode array, null for a scene without LOD.
CATGS_HD bool lod_chunk_merged(const LodNode* nodes, uint64_t c) { return nodes != nullptr && nodes[c].error > 0.0f; }

// The peak opacity a Gaussian is drawn with, from its opacity and its 2D covariance `cov`
// (covariance_2d's, the low-pass kLowPass px^2 on its diagonal). A leaf keeps its opacity: the
// reference 3DGS widens a splat by the low-pass and keeps its peak, as its training did, so a
// sub-pixel leaf covers more than it is. A merged Gaussian (lod_chunk_merged) was fitted to what
// its children cover (lod/lod_fit.h), not trained, so its peak is lowered as the low-pass widens
// it and its alpha integrated over the image stays opacity x 2 pi sqrt(det(cov - kLowPass I)) at
// any distance: sqrt(det(cov - kLowPass I) / det(cov)), the normalisation of Mip-Splatting's 2D
// filter (Yu et al., CVPR 2024, eq. 9). Without it a round merged Gaussian of one pixel's std dev
// covers 1.3 times what it stands for, of half a pixel's 2.2 times (docs/history/level_of_detail.md,
// "Fitted merges"). drawn_scale is that factor (1 for a leaf), drawn_opacity the product.
CATGS_HD float drawn_scale(glm::vec3 cov, bool merged) {
  if (!merged) return 1.0f;
  const float det = cov.x * cov.z - cov.y * cov.y;
  const float det_own = (cov.x - kLowPass) * (cov.z - kLowPass) - cov.y * cov.y;
  return det > 0.0f ? sqrtf(fmaxf(det_own, 0.0f) / det) : 1.0f;
}
CATGS_HD float drawn_opacity(float opacity, glm::vec3 cov, bool merged) { return opacity * drawn_scale(cov, merged); }

// The q_max (opacity_aware_qmax) of a Gaussian drawn at opacity x `scale` (drawn_scale, in
// (0, 1]), from the undrawn opacity's `q_max`, never smaller than the exact 2 ln(255 opacity
// scale): 2 ln(scale) = 8 ln(scale^(1/4)) <= 8 (scale^(1/4) - 1), as ln x <= x - 1. Only
// correctly rounded operations (sqrt, products, sums that never fuse), so the CPU and every CUDA
// kernel list the same tiles: CUDA's logf is not correctly rounded, and a second logf per merged
// Gaussian made the two cores' lists differ (docs/history/level_of_detail.md, "The fitted merges
// on a GPU"). A larger q_max lists a few more tiles; the rasterizers still blend only alpha >=
// 1/255. scale 1 (a leaf) gives q_max itself.
CATGS_HD float drawn_qmax(float q_max, float scale) {
  if (!(scale < 1.0f)) return q_max;
  return lod_add(q_max, lod_mul(8.0f, lod_add(sqrtf(sqrtf(scale)), -1.0f)));
}

// Is chunk c drawn in view v at bound tau (pixels)? `nodes`: the scene's LodNode array (see
// above); tau <= 0 or NaN: the leaves only.
CATGS_HD bool lod_chunk_drawn(const LodNode* nodes, uint64_t c, const View& v, float tau) {
  const LodNode& n = nodes[c];
  if (!(tau > 0.0f)) return n.error == 0.0f;
  const glm::vec3 eye = lod_eye(v);
  const float focal = fmaxf(v.fx, v.fy);
  if (!(lod_error_px(n, eye, focal) <= tau)) return false;
  return n.parent == kLodNoParent || lod_error_px(nodes[n.parent], eye, focal) > tau;
}

// The cut of one frame on the host (the CPU core): `nodes` null for a scene without LOD (every
// chunk drawn). A catgs window takes the cut of its key view for all its sub-frames, so they
// draw the same Gaussians the key frame listed.
struct LodCut {
  const LodNode* nodes = nullptr;
  View view;
  float tau = 0.0f;
  bool drawn(uint64_t c) const { return nodes == nullptr || lod_chunk_drawn(nodes, c, view, tau); }
};
inline LodCut lod_cut(const std::vector<LodNode>& lod, const View& v, float tau) {
  return {lod.empty() ? nullptr : lod.data(), v, tau};
}

// Checks a LOD tree against a model of `gaussians` Gaussians: one node per chunk, leaves (error
// 0) first and every node above them of error > 0, parents at higher chunks, errors finite and
// non-decreasing upwards, boxes nested. Throws std::runtime_error saying which node and what.
// (Empty: no LOD, always fine.)
void validate_lod(const std::vector<LodNode>& lod, std::size_t gaussians);

}  // namespace catgs::fm
