// The compact scene (compact_file.h): per-chunk ranges, per-Gaussian fixed point, parallel blocks.
#include "scene/compact_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstring>

#define XXH_INLINE_ALL  // header-only, as scene_cache.cpp
#include <xxhash.h>

#include "forward_model/lod.h"
#include "ply_format.h"
#include "scene/file_write.h"
#include "scene/load_blocks.h"
#include "scene/quantize.h"
#include "scene/scene_cache.h"
#include "scene/scene_peek.h"

namespace catgs {

namespace {

constexpr char kMagic[8] = {'C', 'A', 'T', 'G', 'S', 'C', 'M', 'P'};
constexpr uint32_t kEndian = 0x01020304u;
constexpr uint64_t kHeaderBytes = 256;
constexpr uint64_t kAlign = 4096;
constexpr uint64_t kChunk = fm::kChunkSize;
constexpr int kShBits = 7;                             // a SH rest coefficient
constexpr int kShLevels = 63;                          // q - 63 in [-63, 63]
constexpr float kPosLevels = 65535.0f;                 // u16 positions
constexpr uint64_t kMaxCompactGaussians = 1ull << 31;  // as the PLY reader's limit

struct CompactHeader {
  char magic[8];
  uint32_t version;
  uint32_t endian;
  uint64_t gaussians;
  uint32_t sh_degree;
  uint32_t chunk_size;
  uint64_t lod_nodes;  // 0 or chunk_count(gaussians)
  SourceStamp source;  // all 0 unless keyed
  uint32_t keyed;
  uint32_t lod_rule;  // fm::kLodMergeRule of the build that made its merged levels; 0: none, or before it
  uint64_t block_gaussians;
  uint64_t record_bytes;
  uint64_t ranges_offset, lod_offset, hashes_offset, data_offset;
  uint64_t blocks;
  uint64_t file_size;
  uint64_t tables_hash;  // XXH3 of the ranges, LOD nodes and block hashes (contiguous)
  uint64_t header_hash;  // XXH3 of every byte above
};
static_assert(sizeof(CompactHeader) <= kHeaderBytes, "the header fits its 256 bytes");

uint64_t sh_rest_bytes(int degree) {
  return (static_cast<uint64_t>(3 * (sh_coeff_count(degree) - 1)) * kShBits + 7) / 8;
}

// The layout for n Gaussians (everything but the source, the hashes and the magic checks).
CompactHeader layout(uint64_t n, int degree, bool lod) {
  CompactHeader h{};
  std::memcpy(h.magic, kMagic, sizeof kMagic);
  h.version = kCompactVersion;
  h.endian = kEndian;
  h.gaussians = n;
  h.sh_degree = static_cast<uint32_t>(degree);
  h.chunk_size = static_cast<uint32_t>(kChunk);
  const uint64_t chunks = fm::chunk_count(n);
  h.lod_nodes = lod ? chunks : 0;
  h.lod_rule = lod ? fm::kLodMergeRule : 0;
  h.block_gaussians = kCompactBlockGaussians;
  h.record_bytes = compact_record_bytes(degree);
  h.blocks = (n + kCompactBlockGaussians - 1) / kCompactBlockGaussians;
  h.ranges_offset = kHeaderBytes;
  h.lod_offset = h.ranges_offset + chunks * sizeof(ChunkRanges);
  h.hashes_offset = h.lod_offset + h.lod_nodes * sizeof(fm::LodNode);
  h.data_offset = (h.hashes_offset + 8 * h.blocks + kAlign - 1) / kAlign * kAlign;
  h.file_size = h.data_offset + n * h.record_bytes;
  return h;
}

uint64_t header_hash(const CompactHeader& h) { return XXH3_64bits(&h, offsetof(CompactHeader, header_hash)); }

// Where one block's fields lie (compact_file.h "data"): `count` Gaussians from `base`.
struct BlockFields {
  uint8_t *pos, *rot, *scale, *colour, *sh;
  uint64_t sh_bytes;
  BlockFields(uint8_t* base, uint64_t count, int degree)
      : pos(base),
        rot(pos + 6 * count),
        scale(rot + 4 * count),
        colour(scale + 4 * count),
        sh(colour + 4 * count),
        sh_bytes(sh_rest_bytes(degree)) {}
};

void put_u32(uint8_t* p, uint32_t v) { std::memcpy(p, &v, 4); }

// memcpy of `n` bytes, nothing when n is 0 (an empty vector's data() may be null, which memcpy
// may not be given even for 0 bytes: UBSan's finding on a scene without LOD).
void copy_bytes(void* to, const void* from, std::size_t n) {
  if (n > 0) std::memcpy(to, from, n);
}
uint32_t get_u32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

int band_of(int k) { return fm::compact_band_of(k); }

float sigmoid(float x) { return 1.0f / (1.0f + std::exp(-x)); }

// Chunk c's ranges over its Gaussians of `m`.
ChunkRanges ranges_of(const GaussianModel& m, uint64_t c) {
  ChunkRanges r;
  for (int a = 0; a < 3; ++a) {
    r.pos_lo[a] = r.scale_lo[a] = r.dc_lo[a] = INFINITY;
    r.pos_hi[a] = r.scale_hi[a] = r.dc_hi[a] = -INFINITY;
    r.band[a] = 0.0f;
  }
  const int K = m.sh_coeffs();
  const uint64_t end = std::min<uint64_t>(m.size(), (c + 1) * kChunk);
  for (uint64_t i = c * kChunk; i < end; ++i) {
    for (int a = 0; a < 3; ++a) {
      const float v[3] = {m.means[3 * i + a], m.log_scales[3 * i + a], m.sh[i * K * 3 + a]};
      float* lo[3] = {r.pos_lo, r.scale_lo, r.dc_lo};
      float* hi[3] = {r.pos_hi, r.scale_hi, r.dc_hi};
      for (int f = 0; f < 3; ++f) {
        lo[f][a] = std::min(lo[f][a], v[f]);
        hi[f][a] = std::max(hi[f][a], v[f]);
      }
    }
    for (int k = 1; k < K; ++k)
      for (int ch = 0; ch < 3; ++ch)
        r.band[band_of(k)] = std::max(r.band[band_of(k)], std::fabs(m.sh[(i * K + k) * 3 + ch]));
  }
  return r;
}

// Empty when every range is finite, ordered and of finite width; else what is wrong.
std::string bad_ranges(const ChunkRanges& r) {
  const float* lo[3] = {r.pos_lo, r.scale_lo, r.dc_lo};
  const float* hi[3] = {r.pos_hi, r.scale_hi, r.dc_hi};
  static const char* const kWhat[3] = {"position", "log-scale", "DC coefficient"};
  for (int f = 0; f < 3; ++f)
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(lo[f][a]) || !std::isfinite(hi[f][a]) || !(lo[f][a] <= hi[f][a]) ||
          !std::isfinite(hi[f][a] - lo[f][a]))
        return std::string(kWhat[f]) + " range not finite or not ordered";
  for (int b = 0; b < 3; ++b)
    if (!std::isfinite(r.band[b]) || !(r.band[b] >= 0.0f)) return "SH band bound not finite or negative";
  return "";
}

// Gaussian i of `m` into slot j of `f`, with its chunk's ranges `r`.
void encode_gaussian(const GaussianModel& m, uint64_t i, const ChunkRanges& r, const BlockFields& f, uint64_t j) {
  const int K = m.sh_coeffs();
  for (int a = 0; a < 3; ++a) {
    const auto q = static_cast<uint16_t>(std::lround(
        std::clamp(quant::normalized(m.means[3 * i + a], r.pos_lo[a], r.pos_hi[a]), 0.0f, 1.0f) * kPosLevels));
    std::memcpy(f.pos + 6 * j + 2 * a, &q, 2);
  }
  put_u32(f.rot + 4 * j, quant::pack_rotation(&m.rotations[4 * i]));
  float t[3];
  for (int a = 0; a < 3; ++a) t[a] = quant::normalized(m.log_scales[3 * i + a], r.scale_lo[a], r.scale_hi[a]);
  put_u32(f.scale + 4 * j, quant::pack_11_10_11(t));
  for (int a = 0; a < 3; ++a)
    f.colour[4 * j + a] =
        static_cast<uint8_t>(quant::unorm_bits(quant::normalized(m.sh[i * K * 3 + a], r.dc_lo[a], r.dc_hi[a]), 8));
  f.colour[4 * j + 3] = static_cast<uint8_t>(quant::unorm_bits(sigmoid(m.opacity_logits[i]), 8));
  uint8_t* out = f.sh + f.sh_bytes * j;
  std::fill_n(out, f.sh_bytes, uint8_t{0});
  uint64_t bit = 0;
  for (int k = 1; k < K; ++k)
    for (int ch = 0; ch < 3; ++ch, bit += kShBits) {
      const float bound = r.band[band_of(k)];
      const float v = bound > 0.0f ? std::clamp(m.sh[(i * K + k) * 3 + ch] / bound, -1.0f, 1.0f) : 0.0f;
      const auto q = static_cast<uint32_t>(std::lround(v * kShLevels) + kShLevels);
      for (int b = 0; b < kShBits; ++b)
        if ((q >> b) & 1u) out[(bit + b) / 8] |= static_cast<uint8_t>(1u << ((bit + b) % 8));
    }
}

// Slot j of `f` into Gaussian i of `m`, with its chunk's ranges `r` (forward_model/compact_codes.h:
// the decode the CUDA core repeats on the codes it keeps).
void decode_gaussian(const BlockFields& f, uint64_t j, const ChunkRanges& r, GaussianModel& m, uint64_t i) {
  const int K = m.sh_coeffs();
  for (int a = 0; a < 3; ++a) {
    uint16_t q;
    std::memcpy(&q, f.pos + 6 * j + 2 * a, 2);
    m.means[3 * i + a] = std::min(r.pos_hi[a], fm::compact_lerp(r.pos_lo[a], r.pos_hi[a], fm::compact_unorm(q, 16)));
  }
  fm::compact_rotation(get_u32(f.rot + 4 * j), &m.rotations[4 * i]);
  fm::compact_log_scales(get_u32(f.scale + 4 * j), r, &m.log_scales[3 * i]);
  for (int a = 0; a < 3; ++a) m.sh[i * K * 3 + a] = fm::compact_dc(f.colour[4 * j + a], r, a);
  m.opacity_logits[i] = compact_opacity_logit(f.colour[4 * j + 3]);
  const uint8_t* codes = f.sh + f.sh_bytes * j;
  int index = 0;
  for (int k = 1; k < K; ++k)
    for (int ch = 0; ch < 3; ++ch, ++index) m.sh[(i * K + k) * 3 + ch] = fm::compact_sh_rest(codes, index, r, k);
}

// Every chunk's ranges, checked writable (finite widths). Throws SceneFileError naming `path`.
std::vector<ChunkRanges> all_ranges(const GaussianModel& m, const std::string& path, int threads) {
  std::vector<ChunkRanges> ranges(fm::chunk_count(m.size()));
  run_blocks(ranges.size(), threads, [&](uint64_t c) {
    ranges[c] = ranges_of(m, c);
    const std::string bad = bad_ranges(ranges[c]);
    if (!bad.empty()) throw SceneFileError(path, "chunk " + std::to_string(c) + ": " + bad + " (cannot quantize)");
  });
  return ranges;
}

void check_writable(const GaussianModel& model, const std::string& path) {
  model.validate();
  if (model.size() == 0) throw SceneFileError(path, "no Gaussians to write");
  if (model.size() > kMaxCompactGaussians) throw SceneFileError(path, "more than 2^31 Gaussians");
}

// XXH3 chained over block b's float arrays (means, log scales, rotations, opacity logits, SH).
uint64_t block_fingerprint(const GaussianModel& m, uint64_t b) {
  const uint64_t first = b * kCompactBlockGaussians, count = std::min(kCompactBlockGaussians, m.size() - first);
  const uint64_t K3 = static_cast<uint64_t>(m.sh_coeffs()) * 3;
  uint64_t h = 0;
  auto add = [&h](const float* v, uint64_t n) { h = XXH3_64bits_withSeed(v, n * sizeof(float), h); };
  add(m.means.data() + 3 * first, 3 * count);
  add(m.log_scales.data() + 3 * first, 3 * count);
  add(m.rotations.data() + 4 * first, 4 * count);
  add(m.opacity_logits.data() + first, count);
  add(m.sh.data() + K3 * first, K3 * count);
  return h;
}

// Empty codes for `m` (ranges filled; the arrays sized, not written).
std::shared_ptr<CompactCodes> new_codes(const GaussianModel& m, std::vector<ChunkRanges> ranges) {
  auto c = std::make_shared<CompactCodes>();
  c->gaussians = m.size();
  c->sh_degree = m.sh_degree;
  c->sh_bytes = static_cast<uint32_t>(sh_rest_bytes(m.sh_degree));
  c->ranges = std::move(ranges);
  c->rotation.resize(m.size());
  c->scale.resize(m.size());
  c->colour.resize(4 * m.size());
  c->sh.resize(c->sh_bytes * m.size());
  c->fingerprints.resize((m.size() + kCompactBlockGaussians - 1) / kCompactBlockGaussians);
  for (uint32_t q = 0; q < 256; ++q) c->opacity_logit[q] = compact_opacity_logit(q);
  return c;
}

// Gaussians [first, first + count) of `f` (slots 0..count) into `c`.
void keep_codes(const BlockFields& f, uint64_t first, uint64_t count, CompactCodes& c) {
  copy_bytes(c.rotation.data() + first, f.rot, 4 * count);
  copy_bytes(c.scale.data() + first, f.scale, 4 * count);
  copy_bytes(c.colour.data() + 4 * first, f.colour, 4 * count);
  copy_bytes(c.sh.data() + c.sh_bytes * first, f.sh, c.sh_bytes * count);  // none at SH degree 0
}

// keep_codes' inverse: Gaussians [first, first + count) of `c` into slots 0..count of `f` (the
// positions are not codes: a decoded mean re-encodes to its own code within its chunk's box).
void restore_codes(const CompactCodes& c, uint64_t first, uint64_t count, const BlockFields& f) {
  copy_bytes(f.rot, c.rotation.data() + first, 4 * count);
  copy_bytes(f.scale, c.scale.data() + first, 4 * count);
  copy_bytes(f.colour, c.colour.data() + 4 * first, 4 * count);
  copy_bytes(f.sh, c.sh.data() + c.sh_bytes * first, c.sh_bytes * count);
}

}  // namespace

float compact_opacity_logit(uint32_t code) {
  const float alpha = fm::compact_unorm(code, 8);
  return code == 0     ? -kOpacityLogitLimit
         : code == 255 ? kOpacityLogitLimit
                       : std::clamp(std::log(alpha / (1.0f - alpha)), -kOpacityLogitLimit, kOpacityLogitLimit);
}

uint64_t compact_record_bytes(int degree) { return 18 + sh_rest_bytes(degree); }

bool compact_codes_match(const GaussianModel& m) {
  const CompactCodes* c = m.codes.get();
  if (!c || c->gaussians != m.size() || c->sh_degree != m.sh_degree || c->ranges.size() != fm::chunk_count(m.size()))
    return false;
  std::vector<uint8_t> same(c->fingerprints.size(), 0);
  run_blocks(same.size(), 0, [&](uint64_t b) { same[b] = block_fingerprint(m, b) == c->fingerprints[b]; });
  return std::all_of(same.begin(), same.end(), [](uint8_t v) { return v != 0; });
}

bool looks_like_compact(const std::vector<uint8_t>& head) {
  return head.size() >= sizeof kMagic && std::memcmp(head.data(), kMagic, sizeof kMagic) == 0;
}

void write_compact_scene(const GaussianModel& model, const std::string& path, const std::string& keyed_to,
                         int threads) {
  check_writable(model, path);
  CompactHeader h = layout(model.size(), model.sh_degree, !model.lod.empty());
  if (!keyed_to.empty()) {
    h.source = source_stamp(keyed_to);
    h.keyed = 1;
  }
  // A model that carries its codes (quantize_compact, a compact read) is written with them, so
  // the file decodes to exactly the arrays it was written from: re-encoding decoded values with
  // ranges taken from them anew could land a value on the next code.
  const CompactCodes* codes = compact_codes_match(model) ? model.codes.get() : nullptr;
  const std::vector<ChunkRanges> ranges = codes ? codes->ranges : all_ranges(model, path, threads);
  // The tables, contiguous as in the file: ranges, LOD nodes, block hashes (filled below).
  std::vector<uint8_t> tables(h.data_offset - h.ranges_offset, 0);
  copy_bytes(tables.data(), ranges.data(), ranges.size() * sizeof(ChunkRanges));
  copy_bytes(tables.data() + (h.lod_offset - h.ranges_offset), model.lod.data(), h.lod_nodes * sizeof(fm::LodNode));
  auto* hashes = tables.data() + (h.hashes_offset - h.ranges_offset);

  write_replacing(path, h.file_size, [&](int fd) {
    run_blocks(h.blocks, threads, [&](uint64_t b) {
      const uint64_t first = b * kCompactBlockGaussians, count = std::min(kCompactBlockGaussians, h.gaussians - first);
      std::vector<uint8_t> bytes(count * h.record_bytes);
      const BlockFields f(bytes.data(), count, model.sh_degree);
      for (uint64_t j = 0; j < count; ++j) encode_gaussian(model, first + j, ranges[(first + j) / kChunk], f, j);
      if (codes) restore_codes(*codes, first, count, f);
      const uint64_t hash = XXH3_64bits(bytes.data(), bytes.size());
      std::memcpy(hashes + 8 * b, &hash, 8);
      write_all(fd, bytes.data(), bytes.size(), h.data_offset + first * h.record_bytes, path);
    });
    h.tables_hash = XXH3_64bits(tables.data(), h.hashes_offset + 8 * h.blocks - h.ranges_offset);
    write_all(fd, tables.data(), tables.size(), h.ranges_offset, path);
    h.header_hash = header_hash(h);
    uint8_t page[kHeaderBytes] = {};
    std::memcpy(page, &h, sizeof h);
    write_all(fd, page, sizeof page, 0, path);
  });
}

void reseal_compact_scene(std::string& bytes) {
  CompactHeader h{};
  if (bytes.size() < kHeaderBytes) return;
  std::memcpy(&h, bytes.data(), sizeof h);
  const uint64_t size = bytes.size();
  auto inside = [size](uint64_t offset, uint64_t n) { return offset <= size && n <= size - offset; };
  const uint64_t block_bytes = h.block_gaussians * h.record_bytes;
  for (uint64_t b = 0; b < h.blocks && inside(h.hashes_offset, 8 * (b + 1)); ++b) {
    if (h.block_gaussians == 0 || h.record_bytes == 0 || block_bytes / h.record_bytes != h.block_gaussians) break;
    const uint64_t first = b * h.block_gaussians;
    if (first >= h.gaussians) break;
    const uint64_t n = std::min(h.block_gaussians, h.gaussians - first) * h.record_bytes;
    const uint64_t at = h.data_offset + b * block_bytes;
    if (at < h.data_offset || !inside(at, n)) continue;
    const uint64_t hash = XXH3_64bits(bytes.data() + at, n);
    std::memcpy(&bytes[h.hashes_offset + 8 * b], &hash, 8);
  }
  if (h.hashes_offset >= h.ranges_offset && h.blocks <= size / 8 &&
      inside(h.ranges_offset, h.hashes_offset - h.ranges_offset + 8 * h.blocks))
    h.tables_hash = XXH3_64bits(bytes.data() + h.ranges_offset, h.hashes_offset + 8 * h.blocks - h.ranges_offset);
  h.header_hash = header_hash(h);
  std::memcpy(bytes.data(), &h, sizeof h);
}

namespace {

// An opened compact file: its header checked against its size, mapped, the tables' hash checked.
struct OpenedCompact {
  CompactHeader h{};
  ply::MappedFile file;
};

OpenedCompact open_compact(const std::string& path) {
  auto bad = [&](const std::string& why) { return SceneFileError(path, "compact scene: " + why); };
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw SceneFileError(path, std::string("cannot stat: ") + std::strerror(errno));
  const auto size = static_cast<uint64_t>(st.st_size);
  if (size < kHeaderBytes) throw bad("truncated: " + std::to_string(size) + " bytes, shorter than its header");
  OpenedCompact o;
  {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw SceneFileError(path, std::string("cannot open: ") + std::strerror(errno));
    const ssize_t got = ::pread(fd, &o.h, sizeof o.h, 0);
    ::close(fd);
    if (got != static_cast<ssize_t>(sizeof o.h)) throw bad("cannot read its header");
  }
  const CompactHeader& h = o.h;
  if (std::memcmp(h.magic, kMagic, sizeof kMagic) != 0) throw bad("no CATGSCMP magic");
  if (h.endian != kEndian) throw bad("written on a machine of another byte order");
  if (h.version != kCompactVersion)
    throw bad("version " + std::to_string(h.version) + ", this build reads version " + std::to_string(kCompactVersion));
  if (header_hash(h) != h.header_hash) throw bad("header checksum mismatch");
  if (h.sh_degree > static_cast<uint32_t>(kMaxShDegree)) throw bad("SH degree " + std::to_string(h.sh_degree));
  if (h.gaussians == 0) throw bad("no Gaussians");
  // Checked before the layout's arithmetic uses the count (every Gaussian takes 18 bytes or more).
  if (h.gaussians > size / 18) throw bad("Gaussian count " + std::to_string(h.gaussians) + " larger than the file");
  if (h.gaussians > kMaxCompactGaussians) throw bad("more than 2^31 Gaussians (the scene readers' limit)");
  const CompactHeader expect = layout(h.gaussians, static_cast<int>(h.sh_degree), h.lod_nodes != 0);
  if (h.chunk_size != expect.chunk_size || h.lod_nodes != expect.lod_nodes ||
      h.block_gaussians != expect.block_gaussians || h.record_bytes != expect.record_bytes ||
      h.ranges_offset != expect.ranges_offset || h.lod_offset != expect.lod_offset ||
      h.hashes_offset != expect.hashes_offset || h.data_offset != expect.data_offset || h.blocks != expect.blocks ||
      h.file_size != expect.file_size)
    throw bad("section layout does not match its Gaussian count");
  if (size != h.file_size)
    throw bad("truncated or extended: " + std::to_string(size) + " bytes, the header says " +
              std::to_string(h.file_size));
  o.file = ply::MappedFile(path, size);
  if (XXH3_64bits(o.file.data() + h.ranges_offset, h.hashes_offset + 8 * h.blocks - h.ranges_offset) != h.tables_hash)
    throw bad("table checksum mismatch");
  return o;
}

GaussianModel decode(const OpenedCompact& o, const std::string& path, int threads, const LoadProgress& progress) {
  const CompactHeader& h = o.h;
  auto bad = [&](const std::string& why) { return SceneFileError(path, "compact scene: " + why); };
  const uint64_t chunks = fm::chunk_count(h.gaussians);
  std::vector<ChunkRanges> ranges(chunks);
  copy_bytes(ranges.data(), o.file.data() + h.ranges_offset, chunks * sizeof(ChunkRanges));
  for (uint64_t c = 0; c < chunks; ++c) {
    const std::string why = bad_ranges(ranges[c]);
    if (!why.empty()) throw bad("chunk " + std::to_string(c) + ": " + why);
  }
  GaussianModel m;
  m.name = scene_name(path);
  m.sh_degree = static_cast<int>(h.sh_degree);
  m.resize(h.gaussians);
  m.lod.resize(h.lod_nodes);
  copy_bytes(m.lod.data(), o.file.data() + h.lod_offset, h.lod_nodes * sizeof(fm::LodNode));
  try {
    fm::validate_lod(m.lod, m.size());
  } catch (const std::exception& e) {
    throw bad(e.what());
  }
  const auto* hashes = o.file.data() + h.hashes_offset;
  const std::shared_ptr<CompactCodes> codes = new_codes(m, ranges);
  run_blocks(
      h.blocks, threads,
      [&](uint64_t b) {
        const uint64_t first = b * kCompactBlockGaussians,
                       count = std::min(kCompactBlockGaussians, h.gaussians - first);
        const uint64_t begin = h.data_offset + first * h.record_bytes, bytes = count * h.record_bytes;
        auto* data = const_cast<uint8_t*>(o.file.data() + begin);  // read only: BlockFields is shared with writing
        uint64_t hash;
        std::memcpy(&hash, hashes + 8 * b, 8);
        if (XXH3_64bits(data, bytes) != hash) throw bad("checksum mismatch in data block " + std::to_string(b));
        const BlockFields f(data, count, m.sh_degree);
        for (uint64_t j = 0; j < count; ++j) decode_gaussian(f, j, ranges[(first + j) / kChunk], m, first + j);
        keep_codes(f, first, count, *codes);
        codes->fingerprints[b] = block_fingerprint(m, b);
        o.file.release(begin, begin + bytes);
      },
      [&](uint64_t done) {
        if (progress && done < h.blocks) progress(done * kCompactBlockGaussians, h.gaussians);
      });
  if (progress) progress(h.gaussians, h.gaussians);
  m.codes = codes;
  return m;
}

}  // namespace

CompactSummary peek_compact(const std::string& path) {
  CompactHeader h{};
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw SceneFileError(path, std::string("cannot open: ") + std::strerror(errno));
  const ssize_t got = ::pread(fd, &h, sizeof h, 0);
  ::close(fd);
  if (got != static_cast<ssize_t>(sizeof h) || std::memcmp(h.magic, kMagic, sizeof kMagic) != 0 ||
      header_hash(h) != h.header_hash || h.sh_degree > static_cast<uint32_t>(kMaxShDegree))
    throw SceneFileError(path, "compact scene: no valid header");
  return {h.gaussians, static_cast<int>(h.sh_degree), h.lod_nodes != 0};
}

GaussianModel read_compact_scene(const std::string& path, const LoadProgress& progress, int threads) {
  return decode(open_compact(path), path, threads, progress);
}

GaussianModel read_compact_lod(const std::string& path, const std::string& scene_path, int threads,
                               const LoadProgress& progress) {
  OpenedCompact o;
  try {
    o = open_compact(path);
  } catch (const SceneFileError& e) {
    throw SceneCacheRejected(path, e.what());
  }
  if (!o.h.keyed) throw SceneCacheRejected(path, "a compact scene served alone, not keyed to a source");
  if (o.h.lod_nodes == 0) throw SceneCacheRejected(path, "a compact scene without a level of detail");
  if (o.h.lod_rule != fm::kLodMergeRule)
    throw SceneCacheRejected(path, "merged levels of merge rule " + std::to_string(o.h.lod_rule) +
                                       ", this build's is " + std::to_string(fm::kLodMergeRule));
  SourceStamp now;
  try {
    now = source_stamp(scene_path);
  } catch (const std::exception& e) {
    throw SceneCacheRejected(path, std::string("cannot check the source: ") + e.what());
  }
  if (now.size != o.h.source.size || now.mtime_ns != o.h.source.mtime_ns || now.head_hash != o.h.source.head_hash)
    throw SceneCacheRejected(path, "the source changed");
  try {
    GaussianModel m = decode(o, path, threads, progress);
    m.name = scene_name(scene_path);
    return m;
  } catch (const SceneFileError& e) {
    throw SceneCacheRejected(path, e.what());
  }
}

void quantize_compact(GaussianModel& model, int threads) {
  check_writable(model, model.name);
  model.codes.reset();
  std::vector<ChunkRanges> ranges = all_ranges(model, model.name, threads);
  const std::shared_ptr<CompactCodes> codes = new_codes(model, std::move(ranges));
  const uint64_t record = compact_record_bytes(model.sh_degree), n = model.size();
  run_blocks(codes->fingerprints.size(), threads, [&](uint64_t b) {
    const uint64_t first = b * kCompactBlockGaussians, count = std::min(kCompactBlockGaussians, n - first);
    std::vector<uint8_t> bytes(count * record);
    const BlockFields f(bytes.data(), count, model.sh_degree);
    for (uint64_t j = 0; j < count; ++j) encode_gaussian(model, first + j, codes->ranges[(first + j) / kChunk], f, j);
    for (uint64_t j = 0; j < count; ++j) decode_gaussian(f, j, codes->ranges[(first + j) / kChunk], model, first + j);
    keep_codes(f, first, count, *codes);
    codes->fingerprints[b] = block_fingerprint(model, b);
  });
  model.codes = codes;
}

}  // namespace catgs
