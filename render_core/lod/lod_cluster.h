// Grouping a LOD node's Gaussians into the clusters that merge into one Gaussian each (issue 37;
// lod_build.h step 2): a median kd split, so a cluster never spans a gap that a split plane
// could cut. Equal Morton runs did: the Morton curve jumps between cells at their boundaries, and
// a run across such a jump merged Gaussians metres apart into one thin, wide Gaussian.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace catgs {

// Reorders `items` (indices of Gaussians; `means` [N, 3] world units, indexed by them) into
// `clusters` >= 1 groups and returns the group bounds: group r is items[bounds[r],
// bounds[r + 1]) (bounds has clusters + 1 entries, bounds[0] = 0, the last items.size()).
// Groups hold floor or ceil of items.size() / clusters items when clusters is a power of two
// (as lod_build's 256 is; empty groups when there are fewer items than clusters). Method: split
// the items at the median of the axis along which their means spread most (the split point at
// the share of items the left half's clusters get), recursively, left half first; ties keep no
// particular order. Throws std::invalid_argument for clusters < 1.
std::vector<std::size_t> kd_clusters(const float* means, std::vector<uint32_t>& items, std::size_t clusters);

}  // namespace catgs
