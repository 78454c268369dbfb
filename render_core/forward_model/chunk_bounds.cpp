// Chunk bounds (chunk_bounds.h), built once per scene on the host.
#include "forward_model/chunk_bounds.h"

#include <algorithm>

#include "base/parallel_for.h"

namespace catgs::fm {

ChunkBounds run_bound(const float* means, const float* log_scales, const float* opacity_logits, std::size_t begin,
                      std::size_t end) {
  ChunkBounds b{glm::vec3(INFINITY), 0.0f, glm::vec3(-INFINITY), 0.0f};  // q_max >= 0: opacity 0 is -inf
  for (std::size_t i = begin; i < end; ++i) {
    const glm::vec3 m(means[3 * i], means[3 * i + 1], means[3 * i + 2]);
    // A NaN coordinate poisons the box (no chunk_outside_view comparison holds on NaN): fminf
    // would skip it, and the Gaussian would go unbounded.
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = std::isnan(m[a]) || std::isnan(b.lo[a]) ? NAN : std::min(b.lo[a], m[a]);
      b.hi[a] = std::isnan(m[a]) || std::isnan(b.hi[a]) ? NAN : std::max(b.hi[a], m[a]);
    }
    const float s = max_scale_of(&log_scales[3 * i]);
    b.max_scale = std::isnan(s) || std::isnan(b.max_scale) ? NAN : std::max(b.max_scale, s);
    const float q = opacity_aware_qmax(sigmoid(opacity_logits[i]));
    b.q_max = std::isnan(q) || std::isnan(b.q_max) ? NAN : std::max(b.q_max, q);
  }
  return b;
}

std::vector<ChunkBounds> chunk_bounds(const float* means, const float* log_scales, const float* opacity_logits,
                                      std::size_t n) {
  std::vector<ChunkBounds> out(chunk_count(n));
  parallel_for(out.size(), 64, [&](std::size_t c) {
    out[c] = run_bound(means, log_scales, opacity_logits, c * kChunkSize, std::min(n, (c + 1) * kChunkSize));
  });
  return out;
}

}  // namespace catgs::fm
