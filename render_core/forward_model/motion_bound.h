// The motion bound M of a catgs key frame (paper sec. 3.1 "Motion Adaptive Adjustment"; issue
// 36): the per-frame screen motion, in pixels, of each mean that counts (on the key image, deeper
// than d) between the key camera and the predicted next one, reduced either to its maximum (the
// paper's M) or to a quantile of a histogram of those motions. Both cores bin each motion with
// motion_bin() and read the quantile with motion_quantile(), so they plan the same window from
// the same counts.
//
// Bins: kMotionBinsPerPixel bins a pixel over [0, kMotionBinnedPixels) px, then one open bin for
// everything faster (and NaN). W = floor(W_initial l / M) is 0 for any M > W_initial l, so
// motions past kMotionBinnedPixels = 64 px (W_initial 4 x l 16) only matter for wider windows;
// a quantile that lands in the open bin is the maximum, as before.
#pragma once

#include <cstdint>

#include "forward_model/forward_model.h"

namespace catgs::fm {

inline constexpr int kMotionBinsPerPixel = 4;
inline constexpr int kMotionBinnedPixels = 64;
inline constexpr int kMotionBins = kMotionBinsPerPixel * kMotionBinnedPixels + 1;  // + the open bin

// The bin of a motion of `m` pixels: floor(m * kMotionBinsPerPixel), the open bin past
// kMotionBinnedPixels or for NaN. Exact in float (a power-of-two scale), so both cores agree.
CATGS_HD int motion_bin(float m) {
  if (!(m < static_cast<float>(kMotionBinnedPixels))) return kMotionBins - 1;
  const int b = static_cast<int>(m * static_cast<float>(kMotionBinsPerPixel));
  return b < 0 ? 0 : b;
}

// M from the histogram `counts` [kMotionBins] of the motions that count and their maximum
// `max_motion` (pixels): the upper edge of the bin that holds the ceil(q * total)-th smallest
// motion, never more than max_motion; max_motion itself for q >= 1, for an empty histogram, or
// when that bin is the open one. Rounding up to the bin's edge keeps M conservative (at most
// 1 / kMotionBinsPerPixel px over the quantile's motion).
inline float motion_quantile(const uint32_t* counts, float max_motion, float q) {
  if (!(q < 1.0f)) return max_motion;
  uint64_t total = 0;
  for (int b = 0; b < kMotionBins; ++b) total += counts[b];
  if (total == 0) return max_motion;
  const double want = static_cast<double>(q) * static_cast<double>(total);
  auto rank = static_cast<uint64_t>(want);
  if (static_cast<double>(rank) < want) ++rank;  // ceil
  if (rank == 0) rank = 1;
  uint64_t seen = 0;
  for (int b = 0; b < kMotionBins - 1; ++b) {
    seen += counts[b];
    if (seen >= rank) {
      const float edge = static_cast<float>(b + 1) / static_cast<float>(kMotionBinsPerPixel);
      return edge < max_motion ? edge : max_motion;
    }
  }
  return max_motion;
}

}  // namespace catgs::fm
