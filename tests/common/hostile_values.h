// Hostile values in a Gaussian model (issue 49), shared by the unit tests, the GPU tests and the
// scene-cache fuzz target: what an attacker who can write a scene's folder puts in a forged scene
// cache or LOD file, or what a bug could hand the render cores straight from memory.
//
// Two kinds:
// - refused: not finite (NaN, +-inf). Every scene reader refuses them (GaussianModel::validate),
//   so a cache or LOD file holding one must be refused too.
// - extreme: finite values far outside any trained scene (a mean of 1e38, a log-scale of 80, an
//   all-zero quaternion, SH coefficients that overflow binary16 with opposite signs). The readers
//   accept them; the render cores must draw a finite image (or end with a clear error), never NaN
//   or an out-of-range tile range.
// Header-only (the GPU tests share it without the unit tests' support files).
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "scene/gaussian_model.h"

namespace catgs::test {

enum class HostileProperty { mean, log_scale, rotation, opacity, sh };

struct HostileCase {
  std::string name;  // "mean NaN", ...
  HostileProperty property;
  float value;         // written into every component of the property (see apply_hostile)
  bool refused;        // not finite: every scene reader refuses it
  const char* reason;  // for refused cases, the words validate() and the cache use ("non-finite mean")
};

inline std::vector<HostileCase> hostile_cases() {
  const float nan = std::nanf(""), inf = INFINITY;
  using P = HostileProperty;
  return {
      {"mean NaN", P::mean, nan, true, "non-finite mean"},
      {"mean +inf", P::mean, inf, true, "non-finite mean"},
      {"mean 1e38", P::mean, 1e38f, false, ""},
      {"log-scale NaN", P::log_scale, nan, true, "non-finite log-scale"},
      {"log-scale +inf", P::log_scale, inf, true, "non-finite log-scale"},
      {"log-scale 80", P::log_scale, 80.0f, false, ""},
      {"log-scale -80", P::log_scale, -80.0f, false, ""},
      {"rotation NaN", P::rotation, nan, true, "non-finite rotation"},
      {"rotation 1e38", P::rotation, 1e38f, false, ""},
      {"rotation all zero", P::rotation, 0.0f, false, ""},
      {"opacity NaN", P::opacity, nan, true, "non-finite opacity"},
      {"opacity -inf", P::opacity, -inf, true, "non-finite opacity"},
      {"opacity 1e38", P::opacity, 1e38f, false, ""},
      {"SH NaN", P::sh, nan, true, "non-finite SH coefficient"},
      {"SH +inf", P::sh, inf, true, "non-finite SH coefficient"},
      // +-1e38 in alternate coefficients: binary16 (the cores' SH storage) rounds both to +-inf,
      // whose sum is NaN.
      {"SH +-1e38", P::sh, 1e38f, false, ""},
  };
}

// Writes the case's value into Gaussians first, first + every, first + 2 every, ... of `m` (every
// component of the property; SH: the value with alternating signs across the coefficients).
inline void apply_hostile(GaussianModel& m, const HostileCase& c, std::size_t first = 0, std::size_t every = 7) {
  const std::size_t k_sh = static_cast<std::size_t>(m.sh_coeffs()) * 3;
  for (std::size_t i = first; i < m.size(); i += every) switch (c.property) {
      case HostileProperty::mean:
        for (int a = 0; a < 3; ++a) m.means[3 * i + a] = c.value;
        break;
      case HostileProperty::log_scale:
        for (int a = 0; a < 3; ++a) m.log_scales[3 * i + a] = c.value;
        break;
      case HostileProperty::rotation:
        for (int a = 0; a < 4; ++a) m.rotations[4 * i + a] = c.value;
        break;
      case HostileProperty::opacity:
        m.opacity_logits[i] = c.value;
        break;
      case HostileProperty::sh:
        for (std::size_t k = 0; k < k_sh; ++k) m.sh[k_sh * i + k] = (k / 3) % 2 == 0 ? c.value : -c.value;
        break;
    }
}

// Number of values of `v` that are not finite.
inline std::size_t count_non_finite(const std::vector<float>& v) {
  std::size_t n = 0;
  for (float x : v) n += std::isfinite(x) ? 0 : 1;
  return n;
}

}  // namespace catgs::test
