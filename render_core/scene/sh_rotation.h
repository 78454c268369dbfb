// Rotating a Gaussian's view-dependent colour with the Gaussian (the city builder turns each copy
// of a scene about its up axis; the glTF reader applies node rotations).
#pragma once

#include <glm/mat3x3.hpp>

namespace catgs {

// Rotates the SH coefficients `sh` [K, 3] (K = (degree + 1)^2, coefficient-major) of a Gaussian
// that is rotated by `R` (world), so its colour seen from direction R d equals the old colour
// seen from d. Exact for bands 1..3 (each band is rotated by a (2l+1)^2 matrix fitted by least
// squares on sample directions, exact up to float rounding since bands are rotation-invariant).
void rotate_sh(int degree, float* sh, const glm::mat3& R);

// Per-band rotation matrices of rotate_sh for one rotation: reuse them for many Gaussians.
struct ShRotation {
  int degree = 0;
  double band[4][7][7] = {};    // band[l] is (2l+1) x (2l+1), row m' col m: c'_m' = sum_m M c_m
  void apply(float* sh) const;  // sh [K, 3]
};
ShRotation make_sh_rotation(int degree, const glm::mat3& R);

}  // namespace catgs
