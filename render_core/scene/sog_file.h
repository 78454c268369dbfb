// PlayCanvas's SOG scene format ("Spatially Ordered Gaussians": a meta.json plus lossless WebP
// images), read into GaussianModel. Versions 2 (current) and 1 (legacy, no "version" key).
//
// Source: PlayCanvas splat-transform 2.7.1, @playcanvas/splat-transform dist/index.mjs: writeSog
// (the writer, version 2), readSog (version 2) and readSogV1 (version 1); and the format page
// developer.playcanvas.com/user-manual/gaussian-splatting/formats/sog/ (version 2). The tests
// compare our reader with splat-transform's decode of the same file, for files it writes (version
// 2, bundled and not) and version 1 files made by the test (tests/unit/sog_reference_test.cpp).
//
// Containers. A bundled `.sog` is a zip archive holding meta.json and the images (stored or
// deflated entries); an unbundled scene is a meta.json with the images beside it (names in
// meta.json are relative to its folder; we refuse absolute names and "..").
//
// Layout. Every image but shN_centroids is W x H RGBA8 with W * H >= count; Gaussian i is texel i in
// row-major order (the writer sorts the Gaussians in Morton order first, which does not matter
// to a reader). Version 2 meta.json: {"version": 2, "count": N, "means": {mins, maxs, files},
// "scales": {codebook, files}, "quats": {files}, "sh0": {codebook, files}, "shN": {count, bands,
// codebook, files} (optional)}:
//   means   means_l.webp (low byte) and means_u.webp (high byte) of 16-bit u per axis (r, g, b);
//           v = min + (max - min) * u / 65535 (a zero range reads as 1), and the position is the
//           inverse of the log transform v = sign(x) * ln(|x| + 1): x = sign(v) * (exp(|v|) - 1)
//   quats   r, g, b: the three smaller components of the unit quaternion (w, x, y, z) with the
//           largest made positive, each c = (byte / 255 * 2 - 1) / sqrt(2), in (w, x, y, z) order
//           skipping the largest; a = 252 + index of the largest (0 = w); the largest is
//           sqrt(1 - sum of squares). Another a is not a quaternion: read as identity, as
//           splat-transform does.
//   scales  r, g, b index a codebook of (up to) 256 log scales, shared by the three axes
//   sh0     r, g, b index a codebook of SH DC coefficients (f_dc); a is sigmoid(opacity) * 255
//   shN     shN_labels.webp: r + 256 g is a palette entry (< shN.count); shN_centroids.webp is
//           64 entries a row, entry e at texels (e % 64) * C + j of row e / 64 for coefficient j
//           = 0..C-1 (C = 3, 8, 15 for bands 1-3), r, g, b index shN.codebook: GaussianModel
//           coefficient j + 1 of each channel.
// Version 1 has "means": {shape: [N, 3], mins, maxs, files} and per-channel ranges instead of
// codebooks: scales and sh0 bytes dequantise linearly, min + (max - min) * byte / 255 (sh0 has
// four ranges; its alpha is an opacity logit, not a sigmoid), shN's scalar mins/maxs likewise;
// shN's bands follow from the centroid image width (192, 512, 960) and its palette from the
// image's size (64 entries a row).
//
// Axes: the writer converts to splat-transform's PLY space (convertToSpace(..., Transform.PLY))
// before packing and the reader hands back a PLY-space table: SOG stores the INRIA PLY's own
// values, the frame GaussianModel uses (RDF for COLMAP captures), so nothing is flipped.
// (PlayCanvas's engine turns PLY space into its own by a 180-degree rotation about z at render.
// The format page calls the frame right-handed "x right, y up, z back"; we follow what
// splat-transform writes and reads, which the tests check.)
//
// Ignored: version 2's optional "antialias" (trained with an anti-aliasing filter; GaussianModel
// has no such mode) and "asset"; splat-transform's decode ignores them too.
//
// Lossy: positions to 16 bits of the log-transformed range per axis; log scales, DC colour and SH
// to 256-entry codebooks (k-means in 1D), and every Gaussian's SH rest coefficients replaced by
// one of shN.count k-means centroids; opacity to 8 bits (alpha 0 or 255 reads as an opacity
// logit of -+kOpacityLogitLimit); quaternion components to 8 bits.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "scene/gaussian_model.h"
#include "scene/load_progress.h"

namespace catgs {

// True when `head` (the first bytes of a file) starts with a zip local file header ("PK\3\4"): a
// bundled .sog (read_sog then requires meta.json inside).
bool looks_like_sog_zip(const std::vector<uint8_t>& head);

// True when `head` is JSON (first non-space byte '{') naming "means" and "files" within the bytes
// given: SOG's meta.json (either version writes means, with its files, first or second).
bool looks_like_sog_meta(const std::vector<uint8_t>& head);

// True when this build can read SOG (libwebp and libzip were found at configure time).
bool sog_supported();

// What meta.json says without decoding any image.
struct SogSummary {
  std::uint64_t gaussians = 0;
  std::optional<int> sh_degree;  // version 2: shN.bands, or 0 without shN; version 1: 0 without shN
};

// Reads meta.json only (from the archive or the file). Throws SceneFileError as read_sog does for
// a container or meta.json it cannot read.
SogSummary peek_sog(const std::string& path);

// Reads a bundled .sog archive or an unbundled meta.json (decided by content, as
// detect_scene_format does). Throws SceneFileError naming `path` for: a build without SOG support,
// a missing or unreadable file, a corrupt zip or an archive without meta.json, invalid JSON, an
// unknown version, a missing or mistyped field (named), a codebook of more than 256 entries or
// non-finite values, a missing image (named), an image that is not lossless WebP or is too small
// for `count` Gaussians, a codebook index or palette label past its table (naming the Gaussian),
// or a Gaussian count of 0 or over 2^31.
GaussianModel read_sog(const std::string& path, const LoadProgress& progress = {});

}  // namespace catgs
