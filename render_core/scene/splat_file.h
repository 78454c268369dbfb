// antimatter15's .splat scene format (read only).
//
// Source: antimatter15/splat (convert.py writes it, main.js reads it); decoded here as
// splat-transform 2.7.1's readSplat decodes it, which the tests compare against.
//
// Layout: no header; N records of 32 bytes, little endian:
//   position  3 x f32      world units
//   scale     3 x f32      linear standard deviations (log taken on reading)
//   colour    4 x u8       r, g, b = 255 * (0.5 + SH_C0 * f_dc); a = 255 * sigmoid(opacity logit)
//   rotation  4 x u8       (w, x, y, z), each 255 * (q + 1) / 2 of the unit quaternion
// Axes: those of the INRIA PLY it was converted from (RDF: x right, y down, z forward), as our
// GaussianModel. Lossy: colour, opacity and rotation at 8 bits; no SH beyond degree 0 (the
// converter drops it). Alpha 0 or 255 reads as an opacity logit of -+kOpacityLogitLimit.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "scene/gaussian_model.h"
#include "scene/load_progress.h"

namespace catgs {

// Whether a file of `file_size` bytes whose first bytes are `head` reads as .splat, which has no
// magic: a whole number of 32-byte records, and every record in `head` (up to 128) with finite
// positions under 1e7, positive finite scales under 1e7 and rotation bytes of a near-unit
// quaternion (|q|^2 in [0.8, 1.2]; convert.py writes 255 (q + 1) / 2 of a unit q, so 8-bit
// rounding moves |q|^2 by under 0.03). Other data (random bytes, text, another format's
// header) fails the first of these within a record or two. `head` must hold at least one record.
bool looks_like_splat(const std::vector<uint8_t>& head, std::uint64_t file_size);

// Reads a .splat file. Throws SceneFileError naming `path` when the file is missing, empty, not
// a whole number of 32-byte records, or holds a NaN or infinite position or a non-positive or
// non-finite scale (named by record and field).
GaussianModel read_splat(const std::string& path, const LoadProgress& progress = {});

}  // namespace catgs
