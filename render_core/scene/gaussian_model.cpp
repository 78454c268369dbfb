#include "scene/gaussian_model.h"

#include "scene/load_blocks.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

namespace catgs {

namespace {

// `v` as n zeros, every core zeroing (and so faulting in) its own blocks of the fresh memory:
// one thread's page faults cost 0.9 s for the 7 M city's 1 GB on the build machine, more than
// parsing it (issue 37), and MADV_POPULATE_WRITE before a serial memset was still several times
// slower on the GPU machine (issue 74, docs/history/scene_loading.md "The model's allocation").
void assign_zeros(ModelArray& v, std::size_t n) {
  ModelArray().swap(v);
  v.resize(n);                              // UninitAllocator: nothing written yet
  constexpr std::size_t kBlock = 16 << 20;  // floats: 64 MiB
  run_blocks((n + kBlock - 1) / kBlock, 0, [&](uint64_t b) {
    const std::size_t from = b * kBlock, to = std::min(n, from + kBlock);
    std::memset(v.data() + from, 0, (to - from) * sizeof(float));
  });
}

}  // namespace

void GaussianModel::resize(std::size_t n) {
  assign_zeros(means, 3 * n);
  assign_zeros(log_scales, 3 * n);
  assign_zeros(rotations, 4 * n);
  assign_zeros(opacity_logits, n);
  assign_zeros(sh, n * static_cast<std::size_t>(sh_coeffs()) * 3);
}

Bounds GaussianModel::bounds() const {
  if (size() == 0) throw std::logic_error("bounds of an empty Gaussian model");
  // Per block on every core, then the blocks' boxes (min and max are exact in any order).
  constexpr std::size_t kBlock = 1 << 18;
  const std::size_t blocks = (size() + kBlock - 1) / kBlock;
  std::vector<Bounds> part(blocks, Bounds{glm::vec3(INFINITY), glm::vec3(-INFINITY)});
  run_blocks(blocks, 0, [&](uint64_t k) {
    Bounds& b = part[k];
    for (std::size_t i = k * kBlock; i < std::min(size(), (k + 1) * kBlock); ++i) {
      const glm::vec3 p(means[3 * i], means[3 * i + 1], means[3 * i + 2]);
      b.min = glm::min(b.min, p);
      b.max = glm::max(b.max, p);
    }
  });
  Bounds b{glm::vec3(INFINITY), glm::vec3(-INFINITY)};
  for (const Bounds& p : part) {
    b.min = glm::min(b.min, p.min);
    b.max = glm::max(b.max, p.max);
  }
  return b;
}

std::size_t first_non_finite(const float* v, std::size_t count) {
  // A float is non-finite exactly when its 8 exponent bits are all ones. The largest exponent
  // field of a run of values is an integer max the compiler vectorises, so the common all-finite
  // case is a scan at memory speed; the index is looked up only in a run that holds one.
  constexpr uint32_t kExponent = 0x7f800000u;
  constexpr std::size_t kRun = 4096;
  for (std::size_t at = 0; at < count; at += kRun) {
    const std::size_t end = std::min(count, at + kRun);
    uint32_t top = 0;
    for (std::size_t k = at; k < end; ++k) {
      uint32_t b;
      std::memcpy(&b, v + k, sizeof b);  // the bits, without breaking aliasing rules
      top = std::max(top, b & kExponent);
    }
    if (top != kExponent) continue;
    for (std::size_t k = at; k < end; ++k)
      if (!std::isfinite(v[k])) return k;
  }
  return count;
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
  auto check = [](const ModelArray& v, std::size_t stride, const char* what) {
    constexpr std::size_t kBlock = 1 << 20;
    run_blocks((v.size() + kBlock - 1) / kBlock, 0, [&](uint64_t b) {
      const std::size_t begin = b * kBlock, count = std::min(v.size(), begin + kBlock) - begin;
      const std::size_t k = first_non_finite(v.data() + begin, count);
      if (k < count)
        throw std::runtime_error(std::string("non-finite ") + what + " of Gaussian " +
                                 std::to_string((begin + k) / stride));
    });
  };
  check(means, 3, "mean");
  check(log_scales, 3, "log-scale");
  check(rotations, 4, "rotation");
  check(opacity_logits, 1, "opacity");
  check(sh, static_cast<std::size_t>(sh_coeffs()) * 3, "SH coefficient");
  fm::validate_lod(lod, n);
}

std::vector<fm::ChunkBounds> chunk_bounds_of(const GaussianModel& model) {
  return fm::chunk_bounds(model.means.data(), model.log_scales.data(), model.opacity_logits.data(), model.size());
}

}  // namespace catgs
