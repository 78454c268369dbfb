// glTF 2.0 (.glb and .gltf) with the KHR_gaussian_splatting extension: read into GaussianModel.
//
// Source: the Khronos KHR_gaussian_splatting extension (github.com/KhronosGroup/glTF,
// extensions/2.0/Khronos/KHR_gaussian_splatting) and, as the independent writer the tests use,
// PlayCanvas splat-transform 2.7.1 (writeGlb in @playcanvas/splat-transform dist/index.mjs).
// splat-transform 2.7.1 writes .glb but cannot read it back.
//
// Layout. One mesh primitive of mode 0 (points) whose extensions hold "KHR_gaussian_splatting";
// its attributes are accessors of N elements each:
//   POSITION                                VEC3 float   centre
//   KHR_gaussian_splatting:ROTATION         VEC4 float   quaternion (x, y, z, w)
//   KHR_gaussian_splatting:SCALE            VEC3 float   standard deviations, linear (not log)
//   KHR_gaussian_splatting:OPACITY          SCALAR float alpha in [0, 1] (not a logit)
//   KHR_gaussian_splatting:SH_DEGREE_l_COEF_n VEC3 float (r, g, b) SH coefficient, l = 0..3,
//                                           n = 0..2l; it is GaussianModel coefficient l*l + n
//   COLOR_0 (optional, ignored)             fallback colour for viewers without the extension
//
// Axes: glTF is right-handed and y-up (glTF 2.0 spec, "Coordinate System and Units"); INRIA PLY
// and GaussianModel are RDF (y down, z forward). splat-transform writes the .glb from PLY data by
// a 180-degree rotation about z (its Transform.PLY), checked on a one-Gaussian file: PLY position
// (1, 2, 3) -> (-1, -2, 3); PLY quaternion (w, x, y, z) = (0.9, 0.1, 0.2, 0.3) -> glTF (x, y, z, w)
// = (-0.2, 0.1, 0.9, -0.3), i.e. q_glTF = q_z * q_PLY with q_z = (w, x, y, z) = (0, 0, 0, 1); SH
// coefficients of odd order m (m = n - l) change sign (degree 1: n = 0 and 2). The reader applies the inverse (the same
// rotation): position (-x, -y, z), q = -(q_z * q_glTF) (the sign gives back the PLY quaternion),
// odd-m SH negated.
//
// Lossy: nothing for float accessors (log/exp of scale and logit/sigmoid of opacity round in the
// last bits; alpha 0 or 1 reads as an opacity logit of -+kOpacityLogitLimit).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "scene/gaussian_model.h"

namespace catgs {

// True when `head` (the first bytes of a file) starts with the .glb magic "glTF", or is JSON (first
// non-space byte '{') that names "KHR_gaussian_splatting" within the bytes given.
bool looks_like_gltf(const std::vector<uint8_t>& head);

// Reads a .glb or .gltf file. Throws SceneFileError naming `path` for a missing or unreadable
// file, invalid glTF, no primitive with KHR_gaussian_splatting, a missing required attribute,
// accessors whose counts disagree, an accessor of the wrong type or component type (not float),
// an SH degree with missing coefficients, or a non-finite value (naming the Gaussian's index and
// the attribute).
GaussianModel read_gltf(const std::string& path);

}  // namespace catgs
