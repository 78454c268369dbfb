// glTF 2.0 (.glb and .gltf) with the KHR_gaussian_splatting extension: read into GaussianModel.
//
// Source: the Khronos KHR_gaussian_splatting extension (github.com/KhronosGroup/glTF,
// extensions/2.0/Khronos/KHR_gaussian_splatting) and, as the independent writer the tests use,
// PlayCanvas splat-transform 2.7.1 (writeGlb in @playcanvas/splat-transform dist/index.mjs).
// splat-transform 2.7.1 writes .glb but cannot read it back.
//
// Layout. Mesh primitives of mode 0 (points) whose extensions hold "KHR_gaussian_splatting";
// the attributes of each are accessors of N elements:
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
// Nodes (glTF 2.0 section 3.5, "Nodes and Hierarchy"): the primitives the default scene draws
// (scene, else scenes[0]) are read, each moved by its node's world transform, the product of its
// ancestors' and its own (a column-major `matrix`, or translation * rotation * scale). A node
// that draws a mesh twice gives two copies; every primitive's Gaussians go into one model (the SH
// degree is the highest any has; the others' higher bands are zero). A Gaussian stays a Gaussian
// under a similarity: the transform, taken to our axes (flip * M * flip), moves its centre,
// composes its rotation, adds log s to its log scales and rotates its SH coefficients
// (scene/sh_rotation.h). Shear, non-uniform scale, reflections and projective rows are refused
// with the node named. A file without scenes: every primitive with the extension, untransformed.
// Checked against splat-transform's own -s/-r/-t actions, which work in glTF's axes
// (tests/unit/gltf_transform_test.cpp).
//
// Component types: float, or (KHR_mesh_quantization) signed/unsigned 8- and 16-bit integers,
// normalized or not, decoded as glTF 2.0 says (normalized signed c -> max(c / (2^(b-1) - 1), -1),
// unsigned c -> c / (2^b - 1)); quantized centres usually come with a node scale and offset.
//
// Lossy: nothing for float accessors (log/exp of scale and logit/sigmoid of opacity round in the
// last bits; alpha 0 or 1 reads as an opacity logit of -+kOpacityLogitLimit); quantized accessors
// lose what their quantization lost.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "scene/gaussian_model.h"
#include "scene/load_progress.h"

namespace catgs {

// True when `head` (the first bytes of a file) starts with the .glb magic "glTF", or is JSON (first
// non-space byte '{') that names "KHR_gaussian_splatting" within the bytes given.
bool looks_like_gltf(const std::vector<uint8_t>& head);

// Reads a .glb or .gltf file. Throws SceneFileError naming `path` for a missing or unreadable
// file, invalid glTF, no primitive with KHR_gaussian_splatting in the default scene, a missing
// required attribute, accessors whose counts disagree, an accessor of the wrong type or component
// type (not float or an 8-/16-bit integer), an SH degree with missing coefficients, a non-finite
// value (naming the Gaussian's index and the attribute), a node transform that is not a
// similarity, or a node tree that names missing nodes or has a cycle.
GaussianModel read_gltf(const std::string& path, const LoadProgress& progress = {});

}  // namespace catgs
