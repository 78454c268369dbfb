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
// INRIA 3DGS PLY: properties x y z, f_dc_0..2, f_rest_* (count decides the SH degree: 0, 9, 24 or
// 45; channel-major f_rest[c * (K-1) + k - 1]), opacity (logit), scale_0..2 (log), rot_0..3
// (w x y z), in any order, float or double, binary_little_endian or ascii; extra properties
// (nx ny nz, ...) are ignored.
// SuperSplat compressed PLY: chunks of 256 Gaussians with min/max ranges, packed 11-10-11
// position and log-scale, 2-10-10-10 smallest-three rotation over (rot_0..rot_3) = (w, x, y, z)
// (top 2 bits: index of the largest; the other three in index order, each * sqrt(2)), 8-8-8-8
// colour + opacity, and an optional `element sh` of uint8 f_rest_* values (q -> (q + 0.5) / 32 - 4,
// 0 -> -4, 255 -> 4). Source: playcanvas/supersplat src/splat-serialize.ts and splat-transform
// 2.7.1's compressed PLY reader; the tests compare against splat-transform's decode.
// Opacity logits of +-inf (INRIA) or alpha 0 / 255 (compressed) clamp to +-kOpacityLogitLimit.
//
// Throws SceneFileError (naming `path`) when the file is missing, is not a PLY, has a malformed
// header (no newline after end_header, a duplicate element), lacks a property, is truncated,
// declares counts the file size cannot hold or whose count x size overflows 64 bits (checked
// before any allocation), has an element with rows but no properties, declares packed_* other
// than uint32 or compressed f_rest_* other than uint8, or holds NaN, an infinite value other
// than an opacity logit, or values beyond float range.
//
// Memory: binary PLY files are memory-mapped and their pages handed back as the rows are read,
// so a load peaks near the model's own size, not the model's plus the file's
// (tests/unit/load_memory_test.cpp measures it). `progress`, when set, is called with (Gaussians
// read, Gaussians in the file), rising, on the loading thread (load_progress.h): every 8192
// Gaussians of a PLY file, every 65536 of an .spz or .splat file (after the .spz's
// decompression), after each glTF primitive, and (N, N) at the end for every format (for SOG
// only that: its images decode whole).
GaussianModel load_scene(const std::string& path, const LoadProgress& progress = {});

// Writes INRIA 3DGS PLY, binary little endian, SH degree of the model. Throws SceneFileError.
void write_inria_ply(const GaussianModel& model, const std::string& path);

// Writes SuperSplat compressed PLY (lossy: see load_scene), with an `element sh` when
// sh_degree > 0. Gaussians are written in the given order, 256 per chunk; sort them spatially
// first (e.g. Morton order) for tight chunk ranges. Throws SceneFileError.
void write_compressed_ply(const GaussianModel& model, const std::string& path);

}  // namespace catgs
