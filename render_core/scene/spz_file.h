// Niantic's .spz scene format (read versions 2-4, write 3 and 4).
//
// Source: the spec in nianticlabs/spz README.md ("File Format") and its reference reader
// src/cc/load-spz.cc; checked against @adobe/spz 0.2.2 (Niantic's reader compiled to WASM), which
// splat-transform 2.7.1 uses to write and read .spz (tests/unit/scene_reference_test.cpp).
//
// Layout. Version 4: a 32-byte header (u32 magic "NGSP", u32 version, u32 N, u8 SH degree, u8
// fractional bits, u8 flags, u8 stream count, u32 TOC offset, 12 reserved bytes), optional
// extension records up to the TOC, a TOC of (u64 compressed, u64 uncompressed) sizes, then one
// zstd stream per attribute. Versions 1-3: the whole file is gzip; inside, a 16-byte header (magic,
// version, N, degree, fractional bits, flags, reserved) and the attributes back to back. Attributes,
// in this order, per Gaussian:
//   positions [N, 3] 24-bit signed fixed point, `fractional bits` of fraction
//   alphas    [N]    u8, sigmoid(logit) * 255
//   colors    [N, 3] u8, f_dc * 0.15 * 255 + 127.5 (the SH DC coefficient, not the colour)
//   scales    [N, 3] u8, (log scale + 10) * 16
//   rotations [N, 4] v3+: u32 LE, top 2 bits the index of the largest of (x, y, z, w), then the
//                    other three in index order, 10 bits each: a sign bit and 9 bits of
//                    |component| / sqrt(1/2); v2: [N, 3] u8 (x, y, z) * 127.5 + 127.5, w >= 0
//   sh        [N, K-1, 3] u8, coefficient-major, channel inner; value (q - 128) / 128
//
// Axes: SPZ stores RUB (x right, y up, z back); INRIA PLY and GaussianModel are RDF (y down, z
// forward), so y and z flip: positions (x, -y, -z), quaternion (w, x, -y, -z), and the SH
// coefficients odd in y xor z change sign (Niantic's flipSh table).
//
// Lossy: positions to 2^-fractional bits units (we write 12 bits, fewer when |x| >= 2048 would
// not fit 24 bits), log scales to 1/16, opacity and DC colour to 8 bits, rotation components to
// 9 bits, SH to 8 bits, written at 5 bits (degree 1) and 4 bits (degree 2, 3) as Niantic's
// writer does. Alpha 0 or 255 reads as an opacity logit of -+kOpacityLogitLimit.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "scene/gaussian_model.h"
#include "scene/load_progress.h"

namespace catgs {

// True when `head` (the first bytes of a file) starts like an .spz file: "NGSP" (v4) or gzip.
bool looks_like_spz(const std::vector<uint8_t>& head);

// Reads an .spz file of version 2, 3 or 4. Throws SceneFileError naming `path` for a missing or
// unreadable file, a bad magic, an unsupported version or SH degree (> 3), a corrupt gzip or zstd
// stream, or streams whose sizes disagree with the header's point count.
GaussianModel read_spz(const std::string& path, const LoadProgress& progress = {});

// Writes an .spz file of `version` 3 (gzip) or 4 (zstd streams; the default). Throws
// SceneFileError naming `path` on an unsupported version, a model of more than 2^32 - 1 Gaussians,
// or a write failure.
void write_spz(const GaussianModel& model, const std::string& path, int version = 4);

}  // namespace catgs
