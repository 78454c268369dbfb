#include "scene/morton.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>

#include "scene/scene_bounds.h"

namespace catgs {

std::vector<uint32_t> morton_order(const GaussianModel& m) {
  const std::size_t n = m.size();
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  if (n == 0) return order;
  const Bounds rb = robust_bounds(m, 0.001f);
  auto spread = [](uint64_t v) {  // 21 bits -> every third bit
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffull;
    v = (v | v << 16) & 0x1f0000ff0000ffull;
    v = (v | v << 8) & 0x100f00f00f00f00full;
    v = (v | v << 4) & 0x10c30c30c30c30c3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
  };
  std::vector<uint64_t> code(n);
  for (std::size_t i = 0; i < n; ++i) {
    uint64_t c = 0;
    for (int a = 0; a < 3; ++a) {
      const float range = rb.max[a] - rb.min[a];
      float t = range > 0.0f ? (m.means[3 * i + a] - rb.min[a]) / range : 0.0f;
      t = std::clamp(t, 0.0f, 1.0f);
      c |= spread(static_cast<uint64_t>(t * 2097151.0f)) << a;
    }
    code[i] = c;
  }
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return code[a] < code[b]; });
  return order;
}

GaussianModel permuted(const GaussianModel& m, const std::vector<uint32_t>& order) {
  if (order.size() != m.size()) throw std::invalid_argument("permuted: order size differs from the model");
  GaussianModel out;
  out.name = m.name;
  out.sh_degree = m.sh_degree;
  out.resize(m.size());
  const std::size_t K3 = static_cast<std::size_t>(m.sh_coeffs()) * 3;
  for (std::size_t i = 0; i < order.size(); ++i) {
    const std::size_t j = order[i];
    if (j >= m.size()) throw std::invalid_argument("permuted: index out of range");
    std::copy_n(&m.means[3 * j], 3, &out.means[3 * i]);
    std::copy_n(&m.log_scales[3 * j], 3, &out.log_scales[3 * i]);
    std::copy_n(&m.rotations[4 * j], 4, &out.rotations[4 * i]);
    out.opacity_logits[i] = m.opacity_logits[j];
    std::copy_n(&m.sh[j * K3], K3, &out.sh[i * K3]);
  }
  return out;
}

}  // namespace catgs
