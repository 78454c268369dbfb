// The LOD tree's checks (lod.h validate_lod).
#include "forward_model/lod.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "forward_model/chunk_bounds.h"

namespace catgs::fm {

void validate_lod(const std::vector<LodNode>& lod, std::size_t gaussians) {
  if (lod.empty()) return;
  if (lod.size() != chunk_count(gaussians))
    throw std::runtime_error("LOD tree of " + std::to_string(lod.size()) + " nodes for " + std::to_string(gaussians) +
                             " Gaussians (" + std::to_string(chunk_count(gaussians)) + " chunks)");
  auto bad = [](std::size_t c, const std::string& what) {
    return std::runtime_error("LOD node " + std::to_string(c) + ": " + what);
  };
  bool above_leaves = false;
  for (std::size_t c = 0; c < lod.size(); ++c) {
    const LodNode& n = lod[c];
    if (!std::isfinite(n.error) || n.error < 0.0f) throw bad(c, "error not finite or negative");
    if (n.error == 0.0f && above_leaves) throw bad(c, "error 0 (a leaf) above a merged node");
    above_leaves = above_leaves || n.error > 0.0f;
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(n.lo[a]) || !std::isfinite(n.hi[a]) || !(n.lo[a] <= n.hi[a]))
        throw bad(c, "empty or non-finite box");
    if (n.parent == kLodNoParent) continue;
    if (n.parent <= c || n.parent >= lod.size())
      throw bad(c, "parent " + std::to_string(n.parent) + " is not a higher chunk of the tree");
    const LodNode& p = lod[n.parent];
    if (p.error == 0.0f || p.error < n.error) throw bad(c, "error above its parent's");
    for (int a = 0; a < 3; ++a)
      if (p.lo[a] > n.lo[a] || p.hi[a] < n.hi[a]) throw bad(c, "box not inside its parent's");
  }
}

}  // namespace catgs::fm
