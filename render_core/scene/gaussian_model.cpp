#include "scene/gaussian_model.h"

#include "scene/load_blocks.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace catgs {

void GaussianModel::resize(std::size_t n) {
  means.assign(3 * n, 0.0f);
  log_scales.assign(3 * n, 0.0f);
  rotations.assign(4 * n, 0.0f);
  opacity_logits.assign(n, 0.0f);
  sh.assign(n * static_cast<std::size_t>(sh_coeffs()) * 3, 0.0f);
}

Bounds GaussianModel::bounds() const {
  if (size() == 0) throw std::logic_error("bounds of an empty Gaussian model");
  Bounds b{glm::vec3(INFINITY), glm::vec3(-INFINITY)};
  for (std::size_t i = 0; i < size(); ++i) {
    const glm::vec3 p(means[3 * i], means[3 * i + 1], means[3 * i + 2]);
    b.min = glm::min(b.min, p);
    b.max = glm::max(b.max, p);
  }
  return b;
}

void GaussianModel::validate() const {
  const std::size_t n = size();
  if (sh_degree < 0 || sh_degree > kMaxShDegree)
    throw std::runtime_error("SH degree " + std::to_string(sh_degree) + " outside 0..3");
  if (means.size() != 3 * n || log_scales.size() != 3 * n || rotations.size() != 4 * n ||
      sh.size() != n * static_cast<std::size_t>(sh_coeffs()) * 3)
    throw std::runtime_error("array sizes disagree with " + std::to_string(n) + " Gaussians");
  // In parallel blocks (load_blocks.h: the lowest failing block's error wins, so the first bad
  // value is named, as a serial walk would).
  auto check = [](const std::vector<float>& v, std::size_t stride, const char* what) {
    constexpr std::size_t kBlock = 1 << 20;
    run_blocks((v.size() + kBlock - 1) / kBlock, 0, [&](uint64_t b) {
      const std::size_t end = std::min(v.size(), (b + 1) * kBlock);
      for (std::size_t k = b * kBlock; k < end; ++k)
        if (!std::isfinite(v[k]))
          throw std::runtime_error(std::string("non-finite ") + what + " of Gaussian " + std::to_string(k / stride));
    });
  };
  check(means, 3, "mean");
  check(log_scales, 3, "log-scale");
  check(rotations, 4, "rotation");
  check(opacity_logits, 1, "opacity");
  check(sh, static_cast<std::size_t>(sh_coeffs()) * 3, "SH coefficient");
}

}  // namespace catgs
