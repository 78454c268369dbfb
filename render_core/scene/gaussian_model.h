// The Gaussian model: N 3D Gaussians as a structure of arrays (docs/DESIGN.md "Scene formats").
#pragma once

#include <cstddef>
#include <stdexcept>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <glm/glm.hpp>

#include "base/bounds.h"
#include "forward_model/chunk_bounds.h"
#include "forward_model/lod.h"

namespace catgs {

inline constexpr int kMaxShDegree = 3;

// Number of SH coefficients per colour channel for a degree: (degree + 1)^2 (1, 4, 9 or 16).
constexpr int sh_coeff_count(int degree) { return (degree + 1) * (degree + 1); }

// Opacity logits of +-inf (alpha exactly 1 or 0, as converters such as splat-transform write them)
// are stored as +-kOpacityLogitLimit: in float, sigmoid(20) is 1.0f and sigmoid(-20) (2e-9) is far
// below the 1/255 alpha a rasterizer draws.
inline constexpr float kOpacityLogitLimit = 20.0f;

// A scene of 3D Gaussians. All arrays are float32, world units, one row per Gaussian:
//   means          [N, 3]  centre (x, y, z)
//   log_scales     [N, 3]  log of the standard deviations along the Gaussian's local axes
//   rotations      [N, 4]  quaternion (w, x, y, z), not necessarily unit (normalised on use)
//   opacity_logits [N]     opacity = sigmoid(logit)
//   sh             [N, K, 3] SH coefficients, K = sh_coeff_count(sh_degree), coefficient-major:
//                  sh[(i * K + k) * 3 + c]; k = 0 is the DC term (INRIA f_dc), k >= 1 the rest.
// (Not [N, 16, 3] whatever the degree: we keep only the K coefficients of the scene's degree so a
// 7 M Gaussian degree-0 city does not carry 15 zero bands.)
// std::allocator, except that value-initialising a float does nothing: resize() leaves new
// elements as they are, so GaussianModel::resize can zero its arrays on every core, each thread
// faulting in its own pages (issue 74: one thread's faults and memset were the read's bound;
// docs/history/scene_loading.md "The model's allocation" has the times).
template <class T>
struct UninitAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UninitAllocator<U>;
  };
  UninitAllocator() = default;
  template <class U>
  UninitAllocator(const UninitAllocator<U>&) noexcept {}
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;  // default-initialised: no write
  }
};
// One of a model's per-Gaussian arrays.
using ModelArray = std::vector<float, UninitAllocator<float>>;

struct CompactCodes;  // scene/compact_file.h

struct GaussianModel {
  std::string name;   // scene name for logs and the protocol (file stem)
  int sh_degree = 0;  // 0..3
  ModelArray means;
  ModelArray log_scales;
  ModelArray rotations;
  ModelArray opacity_logits;
  ModelArray sh;
  // Level of detail (forward_model/lod.h): one node per chunk of kChunkSize Gaussians, or empty
  // (no LOD: every Gaussian is drawn). Built by lod/lod_build.h.
  std::vector<fm::LodNode> lod;
  // The compact scene's codes these arrays were decoded from (scene/compact_file.h: a compact
  // scene's read, quantize_compact), or null. The CUDA core keeps them on the GPU in place of the
  // floats (45 bytes a Gaussian against 98) while they still match the arrays (their
  // fingerprints, compact_codes_match); whatever changes the arrays should drop them.
  std::shared_ptr<const CompactCodes> codes;

  std::size_t size() const { return opacity_logits.size(); }
  int sh_coeffs() const { return sh_coeff_count(sh_degree); }
  // Resizes every array for n Gaussians (contents zeroed, on every core).
  void resize(std::size_t n);
  // Bounds of the means. Throws std::logic_error on an empty model.
  Bounds bounds() const;
  // Checks shapes agree and every value is finite, and the LOD tree (fm::validate_lod); throws
  // std::runtime_error naming the first bad Gaussian and property, or the bad LOD node.
  void validate() const;
};

// Index of the first value of `v[0, count)` that is not finite (NaN or +-inf), or `count` when
// every one is (v may be null when count is 0). The check behind validate() and the scene
// cache's (scene_cache.h): a model's values are finite exactly when every scene reader accepts
// them. Never throws.
std::size_t first_non_finite(const float* v, std::size_t count);

// Thrown for any unreadable or malformed scene file; what() names the file and the problem.
class SceneFileError : public std::runtime_error {
 public:
  SceneFileError(const std::string& path, const std::string& problem) : std::runtime_error(path + ": " + problem) {}
};

// The chunk bounds of `model` (forward_model/chunk_bounds.h), chunk_count(model.size()) entries,
// the culling both cores and the depth probe do before any per-Gaussian work.
std::vector<fm::ChunkBounds> chunk_bounds_of(const GaussianModel& model);

}  // namespace catgs
