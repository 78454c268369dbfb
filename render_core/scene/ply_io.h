// Scene file formats: INRIA 3DGS PLY (read/write) and SuperSplat compressed PLY (read/write).
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "scene/gaussian_model.h"
#include "scene/load_progress.h"

namespace catgs {

// Reads a scene, choosing the format from the header: a file with an `element chunk` and
// `packed_*` vertex properties is SuperSplat compressed PLY, anything else INRIA 3DGS PLY.
//
// INRIA 3DGS PLY. Source: graphdeco-inria/gaussian-splatting, scene/gaussian_model.py
// (construct_list_of_attributes, save_ply, load_ply; the renderer's conventions in
// utils/sh_utils.py and the CUDA rasterizer's computeColorFromSH). One `element vertex` row per
// Gaussian, properties x y z, nx ny nz (written as 0, ignored here), f_dc_0..2, f_rest_*,
// opacity, scale_0..2, rot_0..3; we accept them in any order, float or double,
// binary_little_endian or ascii, and ignore extra properties. Conventions:
//   axes     x y z are world coordinates of the reconstruction the model was trained in: for
//            the reference code, the COLMAP model's world frame and units (arbitrary origin,
//            orientation and scale; no up axis is stored). Its cameras (cameras.json) use the
//            COLMAP/OpenCV camera frame: x right, y down, z forward (camera/trace.h); when the
//            photographer held the camera upright, world up is then roughly -y, nothing more.
//   rotation rot_0..3 = quaternion (w, x, y, z), not necessarily unit (normalised on use);
//            local-to-world, covariance R S S^T R^T.
//   scale    scale_0..2 = log of the standard deviations along the local axes (exp on use).
//   opacity  a logit: opacity = sigmoid(opacity).
//   colour   SH coefficients per RGB channel, K = (degree + 1)^2 per channel: f_dc_c is
//            coefficient 0 of channel c; f_rest is channel-major, f_rest_j = coefficient
//            1 + j % (K - 1) of channel j / (K - 1) (the reference writes features_rest
//            transposed to [N, 3, K - 1]); the count 3 (K - 1) = 0, 9, 24 or 45 gives the
//            degree. Colour = 0.5 + SH_C0 f_dc + higher bands (SH_C0 = 0.28209479), clamped
//            at 0.
//
// SuperSplat compressed PLY. Source: playcanvas/supersplat src/splat-serialize.ts (the writer)
// and playcanvas/engine src/scene/gsplat/gsplat-compressed-data.js / splat-transform 2.7.1's
// reader; the tests compare against splat-transform's decode. `element chunk` rows (one per 256
// Gaussians, in order) hold float ranges min_/max_x y z, min_/max_scale_x y z and, optionally,
// min_/max_r g b; `element vertex` rows hold uint32 packed_position, packed_rotation,
// packed_scale and packed_color; an optional `element sh` holds uint8 f_rest_* in the INRIA
// order above. Same axes, quaternion order and log scales as INRIA PLY after decoding.
// Lossy (what a round trip through write_compressed_ply and this reader loses):
//   position  11-10-11 bits (x in bits 31..21, y 20..11, z 10..0), each the fraction
//             q / (2^bits - 1) of its chunk's [min, max]: steps of (max - min) / 2047 in x and z,
//             / 1023 in y.
//   scale     the same 11-10-11 packing of the log scales within the chunk's min_/max_scale
//             range (the writer clamps log scales to [-20, 20] first).
//   rotation  2 + 3 x 10 bits, smallest three over (rot_0..rot_3) = (w, x, y, z): bits 31..30
//             index the largest |component| (made positive by negating the quaternion, which
//             is the same rotation), the other three in index order in bits 29..20, 19..10,
//             9..0, each q / 1023 - 0.5 scaled by sqrt(2) (range +-1/sqrt(2), steps of
//             sqrt(2) / 1023); the largest is sqrt(1 - the others' squares). The writer
//             normalises first.
//   colour    8 bits a channel (r in bits 31..24, g 23..16, b 15..8) of the DC colour
//             0.5 + SH_C0 f_dc, the fraction q / 255 of the chunk's [min_r, max_r] (of [0, 1]
//             when the chunk has no colour ranges); f_dc = (colour - 0.5) / SH_C0.
//   opacity   8 bits (bits 7..0): alpha = q / 255, the logit ln(alpha / (1 - alpha)); q = 0 and
//             q = 255 (logit -+inf) clamp to -+kOpacityLogitLimit.
//   SH rest   8 bits each, a fixed range [-4, 4] (values outside it clamp): the writer stores
//             floor((v + 4) * 32) (clamped to 0..255), the reader the bucket's centre
//             (q + 0.5) / 32 - 4, except that 0 and 255 read as -4 and 4 (as splat-transform and
//             PlayCanvas's engine read them): error at most 1/64 inside the range, 1/32 in the
//             end buckets.
//   nx ny nz and any other property are not stored.
// Opacity logits of +-inf (INRIA) or alpha 0 / 255 (compressed) clamp to +-kOpacityLogitLimit.
//
// Throws SceneFileError (naming `path`) when the file is missing, is not a PLY, has a malformed
// header (no newline after end_header, a duplicate element), lacks a property, is truncated,
// declares counts the file size cannot hold or whose count x size overflows 64 bits (checked
// before any allocation), has an element with rows but no properties, declares packed_* other
// than uint32 or compressed f_rest_* other than uint8, or holds NaN, an infinite value other
// than an opacity logit, or values beyond float range.
//
// Speed: the rows of a PLY file are parsed in parallel (LoadOptions below; RESULTS.md, "Scene
// loading", has the rates).
// Memory: binary PLY files are memory-mapped and their pages handed back as the rows are read,
// so a load peaks near the model's own size, not the model's plus the file's
// (tests/unit/load_memory_test.cpp measures it). `progress`, when set, is called with (Gaussians
// read, Gaussians in the file), rising, on the loading thread (load_progress.h): every 8192
// Gaussians of a PLY file, every 65536 of an .spz or .splat file (after the .spz's
// decompression), after each glTF primitive, and (N, N) at the end for every format (for SOG
// only that: its images decode whole).
GaussianModel load_scene(const std::string& path, const LoadProgress& progress = {});

// How load_scene reads INRIA and compressed PLY (the other formats read as they always do).
struct LoadOptions {
  // Threads that parse the rows (load_blocks.h): 0 = every hardware thread. Each takes blocks of
  // 8192 consecutive rows; the model, the errors and the progress calls' thread are the same for
  // any count (the first bad row in file order is the one named).
  int threads = 0;
  // The serial reference reader: one thread, every value through the generic typed accessor
  // (tests compare the fast float32 path and the parallel split against it).
  bool reference = false;
};
GaussianModel load_scene(const std::string& path, const LoadOptions& options, const LoadProgress& progress = {});

// Writes INRIA 3DGS PLY, binary little endian, SH degree of the model. Throws SceneFileError.
void write_inria_ply(const GaussianModel& model, const std::string& path);

// Writes SuperSplat compressed PLY (lossy: see load_scene), with an `element sh` when
// sh_degree > 0. Gaussians are written in the given order, 256 per chunk; sort them spatially
// first (e.g. Morton order) for tight chunk ranges. Throws SceneFileError.
void write_compressed_ply(const GaussianModel& model, const std::string& path);

}  // namespace catgs
