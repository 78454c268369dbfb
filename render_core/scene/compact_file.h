// The compact scene (issue 74): the scene as the server keeps it, with its level of detail, in
// 39 bytes a Gaussian at SH degree 2 plus its chunk's share (the layout below; sizes against the
// float LOD file and the PLY: RESULTS.md "Compact scene"). Our own format, quantized per chunk of fm::kChunkSize Gaussians, so that a chunk's range
// serves both the cut's culling and the quantization. `catgs-scene lod --out F.catgs`, `convert`
// and `tile` write it; load_scene reads it by its magic (it is served alone: --scene F.catgs);
// the server writes its LOD files in it (scene_with_lod.h), keyed to their source.
//
// Layout (little endian; offsets from the file's start):
//   0        CompactHeader (compact_file.cpp), 256 bytes: magic "CATGSCMP", version, byte order
//            mark, N (Gaussians, padding of a LOD's chunks included), SH degree, chunk size (256),
//            LOD nodes (0 or chunk_count(N)), the source stamp of a keyed file (size,
//            modification time in ns, XXH3 of its first 64 KiB; all 0 in a file served alone),
//            the rule its merged levels were made by (fm::kLodMergeRule; 0 before rule 2: a keyed
//            LOD file of another rule is rebuilt, a file served alone draws its merges as they are),
//            the sections' offsets, the file size, an XXH3 of the tables and of the header.
//   tables   the chunk ranges [chunk_count(N)] (fm::ChunkRanges, forward_model/compact_codes.h, 84 bytes), the LOD nodes
//            [0 or chunk_count(N)] (fm::LodNode, 32 bytes), the XXH3-64 of each data block
//            [blocks] (8 bytes)
//   data     at a 4096-byte boundary: blocks of kCompactBlockGaussians Gaussians (the last one
//            shorter), each its Gaussians' fields one after another (per Gaussian, in order):
//              position  [3] u16: q / 65535 of the chunk's [lo, hi] per axis (the decode is
//                        clamped to hi), steps of (hi - lo) / 65535
//              rotation  u32: smallest three (quantize.h pack_rotation) over (w, x, y, z)
//              scale     u32: the log scales, 11-10-11 bits (quantize.h) of the chunk's range
//              colour    [4] u8: the DC coefficients (f_dc, not the colour) q / 255 of the chunk's
//                        range per channel, then alpha = q / 255 (0 and 255 read as the opacity
//                        logits -+kOpacityLogitLimit)
//              sh rest   ceil(7 x 3 (K - 1) / 8) bytes: each coefficient k >= 1 of each channel
//                        (the model's order: coefficient-major, channel inner) in 7 bits, LSB
//                        first, value (q - 63) / 63 x the chunk's absolute bound of its band
//                        (k 1-3: band 1, 4-8: band 2, 9-15: band 3); q 127 is never written
//            So 6 + 4 + 4 + 4 + 21 = 39 bytes a Gaussian at SH degree 2 (18 + 8, 18 + 40 at 1, 3),
//            plus 116 bytes a chunk (0.45 a Gaussian). The decode's exact arithmetic (the
//            fractions are q times the float nearest 1 / (2^bits - 1)): forward_model/compact_codes.h,
//            which the CUDA core shares.
// The tables' and the blocks' hashes detect damage, not forgery. What a forged file can still
// say is checked as for every scene file: counts against the file's size before any allocation,
// ranges finite with lo <= hi (so every decoded value is finite), the LOD tree
// (fm::validate_lod). Every failure is a SceneFileError naming the file and what is wrong.
//
// Lossy, what write then read loses (quantize_compact applies exactly that to a model in memory):
// positions to (hi - lo) / 131070 of their chunk's box, log scales to 1/4094 (x, z) and 1/2046 (y)
// of their chunk's range, rotations as compressed PLY, DC coefficients to 1/510 of their chunk's
// range, opacity to 1/510, SH rest to 1/126 of their band's bound. Where the picture lands is
// measured by catgs-bench's yardstick (RESULTS.md "Compact scene"). A SuperSplat compressed PLY
// written in its own order (catgs-scene convert keeps it) loses none of its codes: each chunk's
// ranges lie within the source chunk's, at no coarser steps (positions 16 against 11/10 bits, log
// scales 11-10-11 and colours 8 bits of a range no wider), alpha is the same 8 bits and rotations
// keep their words (quantize.h pack_rotation); its 8-bit SH rest buckets of [-4, 4] come back while
// a chunk's band bound stays under about 2 (7 bits of it). A LOD built in the source's order
// (lod/lod_build.h keep_order: catgs-scene lod and the server do for a compressed PLY) keeps them
// in its leaves too. Re-sorted, a chunk mixes source chunks and a value moves by up to half its
// new step.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "forward_model/compact_codes.h"
#include "scene/gaussian_model.h"
#include "scene/load_progress.h"

namespace catgs {

inline constexpr uint32_t kCompactVersion = 1;
inline constexpr uint64_t kCompactBlockGaussians = 65536;  // a data block: hashed and decoded by one thread

using fm::ChunkRanges;  // forward_model/compact_codes.h: a chunk's ranges, and the decode both cores share

// The opacity logit of an 8-bit alpha code q (alpha = q / 255; 0 and 255 give
// -+kOpacityLogitLimit). The CUDA core reads these 256 values from a table (std::log differs
// between host and device in its last bits).
float compact_opacity_logit(uint32_t code);

// Bytes a Gaussian takes in the data blocks at SH degree `degree` (0..3).
uint64_t compact_record_bytes(int degree);

// True when `head` (the first bytes of a file) starts with the compact scene's magic.
bool looks_like_compact(const std::vector<uint8_t>& head);

// Writes `model` (validated first; its Gaussians in chunk order as they are: sort a plain scene
// spatially first, e.g. Morton order, for tight ranges; a LOD model is) as a compact scene at
// `path`, through a temporary file renamed into place. `keyed_to` non-empty: the file records that
// scene file's stamp (a LOD file in a cache folder, checked by read_compact_lod); empty: a file
// served alone. `threads` as LoadOptions::threads. Throws SceneFileError naming the file (a model
// over 2^31 Gaussians, a range whose width overflows float, keyed_to unreadable, a write
// failure), std::runtime_error for an invalid model.
void write_compact_scene(const GaussianModel& model, const std::string& path, const std::string& keyed_to = "",
                         int threads = 0);

// A compact scene's codes as the CUDA core keeps them (cuda/cuda_renderer.h DeviceScene), beside
// the float model they were decoded into: per Gaussian its rotation, log-scale, colour (DC and
// alpha) and SH rest codes as in the file, per chunk its ranges, and per data block a fingerprint
// of the block's float arrays (compact_codes_match). The means stay float on the GPU (the cut,
// culling and depth read them for every Gaussian of a drawn chunk). 4 + 4 + 4 + 21 bytes a
// Gaussian on the host at SH degree 2.
struct CompactCodes {
  template <class T>
  using Array = std::vector<T, UninitAllocator<T>>;  // filled in parallel by the decode
  uint64_t gaussians = 0;
  int sh_degree = 0;
  uint32_t sh_bytes = 0;               // a Gaussian's SH rest codes
  std::vector<ChunkRanges> ranges;     // [chunk_count(N)]
  Array<uint32_t> rotation, scale;     // [N]
  Array<uint8_t> colour;               // [N, 4]: DC red, green, blue, alpha
  Array<uint8_t> sh;                   // [N, sh_bytes]
  std::vector<uint64_t> fingerprints;  // [blocks of kCompactBlockGaussians]
  float opacity_logit[256] = {};       // compact_opacity_logit of each alpha code
};

// Whether `model.codes` still decode to `model`'s arrays: the same counts and every block's
// fingerprint (an XXH3 over its floats) unchanged. Runs on every core; false without codes.
bool compact_codes_match(const GaussianModel& model);

// What a compact file's header says (its magic and header checksum checked, nothing else): for
// listing scenes (scene_peek.h). Throws SceneFileError naming `path`.
struct CompactSummary {
  uint64_t gaussians = 0;  // merged levels included
  int sh_degree = 0;
  bool lod = false;
};
CompactSummary peek_compact(const std::string& path);

// Reads a compact scene (load_scene calls it for a file with the magic): the model as written,
// quantized, with its LOD tree when it has one and its codes (GaussianModel::codes); name =
// scene_name(path). Throws SceneFileError naming `path` (see above). Memory: the file is mapped
// and its pages handed back block by block.
GaussianModel read_compact_scene(const std::string& path, const LoadProgress& progress = {}, int threads = 0);

// A LOD file in compact form (the server's cache folder, catgs-scene lod): as read_compact_scene,
// and the file must be keyed to `scene_path` as that file is now and hold a LOD tree. Throws
// SceneCacheRejected (scene_cache.h) naming `path` and why.
GaussianModel read_compact_lod(const std::string& path, const std::string& scene_path, int threads = 0,
                               const LoadProgress& progress = {});

// Forges a compact file as an attacker with write access could: recomputes, in the file image
// `bytes`, every data block's hash, the tables' hash and the header's, from the header's own
// layout fields whatever they say (a block or table outside `bytes` is skipped; `bytes` shorter
// than a header is left as it is). For the tests and the fuzz target, so they reach the checks
// behind the hashes.
void reseal_compact_scene(std::string& bytes);

// Quantizes `model` in place exactly as write_compact_scene then read_compact_scene would, codes
// included (so the server that builds a LOD draws on its first start what it draws from the file
// afterwards). Throws as write_compact_scene does.
void quantize_compact(GaussianModel& model, int threads = 0);

}  // namespace catgs
