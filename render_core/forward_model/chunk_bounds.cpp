// Chunk bounds (chunk_bounds.h), built once per scene on the host.
#include "forward_model/chunk_bounds.h"

#include <algorithm>

#include "cpu/cpu_renderer.h"  // parallel_for
#include "scene/gaussian_model.h"

namespace catgs::fm {

std::vector<ChunkBounds> chunk_bounds(const GaussianModel& model) {
  const std::size_t n = model.size();
  std::vector<ChunkBounds> out(chunk_count(n));
  cpu::parallel_for(out.size(), 64, [&](std::size_t c) {
    ChunkBounds b{glm::vec3(INFINITY), 0.0f, glm::vec3(-INFINITY), 0.0f};  // q_max >= 0: opacity 0 is -inf
    const std::size_t end = std::min(n, (c + 1) * kChunkSize);
    for (std::size_t i = c * kChunkSize; i < end; ++i) {
      const glm::vec3 m(model.means[3 * i], model.means[3 * i + 1], model.means[3 * i + 2]);
      // A NaN coordinate poisons the box (no chunk_outside_view comparison holds on NaN): fminf
      // would skip it, and the Gaussian would go unbounded.
      for (int a = 0; a < 3; ++a) {
        b.lo[a] = std::isnan(m[a]) || std::isnan(b.lo[a]) ? NAN : std::min(b.lo[a], m[a]);
        b.hi[a] = std::isnan(m[a]) || std::isnan(b.hi[a]) ? NAN : std::max(b.hi[a], m[a]);
      }
      const float s = max_scale_of(&model.log_scales[3 * i]);
      b.max_scale = std::isnan(s) || std::isnan(b.max_scale) ? NAN : std::max(b.max_scale, s);
      const float q = opacity_aware_qmax(sigmoid(model.opacity_logits[i]));
      b.q_max = std::isnan(q) || std::isnan(b.q_max) ? NAN : std::max(b.q_max, q);
    }
    out[c] = b;
  });
  return out;
}

}  // namespace catgs::fm
