// .spz reader and writer (layout, axes and losses in spz_file.h).
#include "scene/spz_file.h"

#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>

namespace catgs {

namespace {

constexpr uint32_t kMagic = 0x5053474e;  // "NGSP" in file order
constexpr float kColorScale = 0.15f;
constexpr float kSqrtHalf = 0.70710678118654752f;
// A corrupt or hostile file must not make us allocate without bound: Niantic's reader caps the
// decompressed size at 1024 times the file size; so do we.
constexpr uint64_t kMaxExpansion = 1024;
// Sign of each SH rest coefficient (degrees 1-3, INRIA order) under RDF <-> RUB (y, z negated).
constexpr std::array<float, 15> kShFlip = {-1, -1, 1, -1, 1, 1, -1, 1, -1, 1, -1, -1, 1, -1, 1};

[[noreturn]] void fail(const std::string& path, const std::string& problem) { throw SceneFileError(path, problem); }

std::vector<uint8_t> read_all(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open file");
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

template <typename T>
T load(const uint8_t* at) {
  T v;
  std::memcpy(&v, at, sizeof v);
  return v;
}

// The attribute streams of one file, in the order of the layout.
struct Streams {
  uint32_t version = 0, count = 0;
  int sh_degree = 0, fractional_bits = 0;
  std::vector<uint8_t> positions, alphas, colors, scales, rotations, sh;
};

std::size_t rotation_bytes(uint32_t version) { return version >= 3 ? 4 : 3; }

// Expected byte size of each stream, in layout order.
std::array<uint64_t, 6> stream_sizes(const Streams& s) {
  const uint64_t n = s.count, rest = static_cast<uint64_t>(sh_coeff_count(s.sh_degree) - 1);
  return {n * 9, n, n * 3, n * 3, n * rotation_bytes(s.version), n * rest * 3};
}

std::array<std::vector<uint8_t>*, 6> stream_slots(Streams& s) {
  return {&s.positions, &s.alphas, &s.colors, &s.scales, &s.rotations, &s.sh};
}

void check_header(const Streams& s, const std::string& path) {
  if (s.version < 2 || s.version > 4)
    fail(path, "unsupported .spz version " + std::to_string(s.version) + " (2, 3 and 4 are read)");
  if (s.sh_degree < 0 || s.sh_degree > kMaxShDegree)
    fail(path, ".spz SH degree " + std::to_string(s.sh_degree) + " is not supported (0..3)");
  if (s.fractional_bits > 23) fail(path, ".spz fractional bits " + std::to_string(s.fractional_bits) + " > 23");
  if (s.count == 0) fail(path, "the scene holds no Gaussians (point count 0)");
}

std::vector<uint8_t> gunzip(const std::vector<uint8_t>& in, const std::string& path) {
  z_stream z{};
  if (inflateInit2(&z, 16 + MAX_WBITS) != Z_OK) fail(path, "zlib inflateInit2 failed");
  std::vector<uint8_t> out;
  const uint64_t limit = kMaxExpansion * in.size();
  z.next_in = const_cast<Bytef*>(in.data());
  z.avail_in = static_cast<uInt>(in.size());
  int rc = Z_OK;
  while (rc != Z_STREAM_END) {
    if (out.size() >= limit) {
      inflateEnd(&z);
      fail(path, "gzip body expands beyond " + std::to_string(kMaxExpansion) + "x the file size");
    }
    const std::size_t at = out.size();
    out.resize(std::max<std::size_t>(at * 2, 1 << 20));
    z.next_out = out.data() + at;
    z.avail_out = static_cast<uInt>(out.size() - at);
    rc = inflate(&z, Z_NO_FLUSH);
    out.resize(out.size() - z.avail_out);
    if (rc != Z_OK && rc != Z_STREAM_END) {
      inflateEnd(&z);
      fail(path, "corrupt or truncated gzip body (zlib error " + std::to_string(rc) + ")");
    }
  }
  inflateEnd(&z);
  return out;
}

// Versions 1-3: gzip of [16-byte header][streams back to back].
Streams parse_legacy(const std::vector<uint8_t>& file, const std::string& path) {
  const std::vector<uint8_t> body = gunzip(file, path);
  if (body.size() < 16) fail(path, "gzip body shorter than the 16-byte .spz header");
  if (load<uint32_t>(body.data()) != kMagic) fail(path, "gzip body lacks the .spz magic 'NGSP'");
  Streams s;
  s.version = load<uint32_t>(body.data() + 4);
  s.count = load<uint32_t>(body.data() + 8);
  s.sh_degree = body[12];
  s.fractional_bits = body[13];
  check_header(s, path);
  std::size_t at = 16;
  const auto sizes = stream_sizes(s);
  const auto slots = stream_slots(s);
  for (std::size_t k = 0; k < 6; ++k) {
    if (sizes[k] > body.size() - at)
      fail(path, "truncated: " + std::to_string(s.count) + " Gaussians need more than the " +
                     std::to_string(body.size()) + " bytes the gzip body holds");
    slots[k]->assign(body.begin() + static_cast<std::ptrdiff_t>(at),
                     body.begin() + static_cast<std::ptrdiff_t>(at + sizes[k]));
    at += sizes[k];
  }
  return s;  // trailing bytes are extension records, which we do not use
}

// Version 4: [32-byte header][extensions][TOC][zstd streams].
Streams parse_ngsp(const std::vector<uint8_t>& file, const std::string& path) {
  if (file.size() < 32) fail(path, "truncated: shorter than the 32-byte .spz header");
  Streams s;
  s.version = load<uint32_t>(file.data() + 4);
  s.count = load<uint32_t>(file.data() + 8);
  s.sh_degree = file[12];
  s.fractional_bits = file[13];
  const unsigned streams = file[15];
  const uint64_t toc = load<uint32_t>(file.data() + 16);
  if (s.version < 4) fail(path, "plain 'NGSP' header with version " + std::to_string(s.version) + " (must be gzip)");
  check_header(s, path);
  if (streams < 5 || streams > 6) fail(path, ".spz declares " + std::to_string(streams) + " streams (5 or 6)");
  if (toc < 32 || toc + streams * 16ull > file.size()) fail(path, "truncated: the .spz TOC lies past the end");
  const auto sizes = stream_sizes(s);
  const auto slots = stream_slots(s);
  uint64_t total = 0;
  for (uint64_t n : sizes) total += n;
  if (total > kMaxExpansion * file.size())  // checked before any allocation the header could inflate
    fail(path, std::to_string(s.count) + " Gaussians declared: more than " + std::to_string(kMaxExpansion) +
                   "x the file size once decompressed");
  uint64_t at = toc + streams * 16ull;
  for (unsigned k = 0; k < 6; ++k) {
    if (k >= streams) {  // no SH stream: only valid for degree 0
      if (sizes[k] != 0) fail(path, ".spz of SH degree " + std::to_string(s.sh_degree) + " lacks its SH stream");
      continue;
    }
    const uint64_t packed = load<uint64_t>(file.data() + toc + 16 * k);
    const uint64_t plain = load<uint64_t>(file.data() + toc + 16 * k + 8);
    if (plain != sizes[k])
      fail(path, "stream " + std::to_string(k) + " holds " + std::to_string(plain) + " bytes, " +
                     std::to_string(s.count) + " Gaussians need " + std::to_string(sizes[k]));
    if (packed > file.size() - at) fail(path, "truncated: stream " + std::to_string(k) + " runs past the end");
    slots[k]->resize(plain);
    const std::size_t got = ZSTD_decompress(slots[k]->data(), plain, file.data() + at, packed);
    if (ZSTD_isError(got) || got != plain)
      fail(path, "corrupt zstd stream " + std::to_string(k) +
                     (ZSTD_isError(got) ? std::string(": ") + ZSTD_getErrorName(got) : std::string()));
    at += packed;
  }
  return s;
}

// v3+: smallest three of (x, y, z, w) -> GaussianModel (w, x, y, z), still in RUB.
void unpack_smallest_three(const uint8_t* r, float* wxyz) {
  uint32_t comp = load<uint32_t>(r);
  const unsigned largest = comp >> 30;
  float xyzw[4];
  float sum = 0;
  for (int k = 3; k >= 0; --k) {
    if (static_cast<unsigned>(k) == largest) continue;
    const float mag = kSqrtHalf * static_cast<float>(comp & 511u) / 511.0f;
    xyzw[k] = (comp >> 9) & 1u ? -mag : mag;
    sum += xyzw[k] * xyzw[k];
    comp >>= 10;
  }
  xyzw[largest] = std::sqrt(std::max(0.0f, 1.0f - sum));
  wxyz[0] = xyzw[3];
  for (int k = 0; k < 3; ++k) wxyz[1 + k] = xyzw[k];
}

// v2: (x, y, z) at 8 bits, w >= 0 from the unit norm.
void unpack_first_three(const uint8_t* r, float* wxyz) {
  float sum = 0;
  for (int k = 0; k < 3; ++k) {
    wxyz[1 + k] = static_cast<float>(r[k]) / 127.5f - 1.0f;
    sum += wxyz[1 + k] * wxyz[1 + k];
  }
  wxyz[0] = std::sqrt(std::max(0.0f, 1.0f - sum));
}

float opacity_logit_of_byte(uint8_t a) {
  if (a == 0) return -kOpacityLogitLimit;
  if (a == 255) return kOpacityLogitLimit;
  const float t = static_cast<float>(a) / 255.0f;
  return std::log(t / (1.0f - t));
}

GaussianModel to_model(const Streams& s, const LoadProgress& progress) {
  const ProgressSteps steps(progress, s.count);
  GaussianModel m;
  m.sh_degree = s.sh_degree;
  m.resize(s.count);
  const std::size_t K = static_cast<std::size_t>(m.sh_coeffs());
  const float unit = std::ldexp(1.0f, -s.fractional_bits);
  const float flip[3] = {1, -1, -1};  // RUB -> RDF
  for (std::size_t i = 0; i < s.count; ++i) {
    steps.at(i);
    for (int a = 0; a < 3; ++a) {
      const uint8_t* p = &s.positions[9 * i + 3 * a];
      int32_t fixed = p[0] | (p[1] << 8) | (p[2] << 16);
      if (fixed & 0x800000) fixed -= 1 << 24;  // sign-extend 24 bits
      m.means[3 * i + a] = flip[a] * static_cast<float>(fixed) * unit;
      m.log_scales[3 * i + a] = static_cast<float>(s.scales[3 * i + a]) / 16.0f - 10.0f;
      m.sh[i * K * 3 + a] = (static_cast<float>(s.colors[3 * i + a]) / 255.0f - 0.5f) / kColorScale;
    }
    m.opacity_logits[i] = opacity_logit_of_byte(s.alphas[i]);
    float* q = &m.rotations[4 * i];
    if (s.version >= 3)
      unpack_smallest_three(&s.rotations[4 * i], q);
    else
      unpack_first_three(&s.rotations[3 * i], q);
    q[2] = -q[2];  // a 180-degree turn about x: (w, x, -y, -z)
    q[3] = -q[3];
    for (std::size_t k = 1; k < K; ++k)
      for (std::size_t c = 0; c < 3; ++c)
        m.sh[(i * K + k) * 3 + c] =
            kShFlip[k - 1] * (static_cast<float>(s.sh[(i * (K - 1) + k - 1) * 3 + c]) - 128.0f) / 128.0f;
  }
  steps.done();
  return m;
}

// --- writing ---------------------------------------------------------------------------------

uint8_t to_u8(float x) { return static_cast<uint8_t>(std::clamp(std::round(x), 0.0f, 255.0f)); }

// 8-bit SH, rounded to the centre of a bucket of `bucket` codes (Niantic's quantizeSH): fewer
// distinct values compress better, and 0 stays exact.
uint8_t quantize_sh(float x, int bucket) {
  int q = static_cast<int>(std::round(std::clamp(x, -1.0f, 1.0f) * 128.0f)) + 128;
  q = (q + bucket / 2) / bucket * bucket;
  return static_cast<uint8_t>(std::clamp(q, 0, 255));
}

// (w, x, y, z) in RDF -> smallest three of (x, y, z, w) in RUB, u32 little endian.
void pack_smallest_three(const float* wxyz, uint8_t* out) {
  float q[4] = {wxyz[1], -wxyz[2], -wxyz[3], wxyz[0]};
  const float len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  unsigned largest = 3;
  for (unsigned k = 0; k < 4; ++k) {
    q[k] = len > 0 ? q[k] / len : (k == 3 ? 1.0f : 0.0f);
    if (std::fabs(q[k]) > std::fabs(q[largest])) largest = k;
  }
  const bool negate = q[largest] < 0;  // q and -q are one rotation: make the dropped one positive
  uint32_t comp = largest;
  for (unsigned k = 0; k < 4; ++k) {
    if (k == largest) continue;
    const uint32_t sign = (q[k] < 0) != negate ? 1u : 0u;
    const auto mag = static_cast<uint32_t>(std::min(511.0f, 511.0f * std::fabs(q[k]) / kSqrtHalf + 0.5f));
    comp = (comp << 10) | (sign << 9) | mag;
  }
  std::memcpy(out, &comp, 4);
}

// The largest fractional bit count <= 12 whose 24-bit range holds every coordinate.
int fractional_bits_for(const GaussianModel& m) {
  float reach = 0;
  for (float v : m.means) reach = std::max(reach, std::fabs(v));
  int bits = 12;
  while (bits > 0 && reach * std::ldexp(1.0f, bits) >= 8388607.0f) --bits;
  return bits;
}

Streams from_model(const GaussianModel& m, int version) {
  Streams s;
  s.version = static_cast<uint32_t>(version);
  s.count = static_cast<uint32_t>(m.size());
  s.sh_degree = m.sh_degree;
  s.fractional_bits = fractional_bits_for(m);
  const auto sizes = stream_sizes(s);
  const auto slots = stream_slots(s);
  for (std::size_t k = 0; k < 6; ++k) slots[k]->resize(sizes[k]);
  const std::size_t K = static_cast<std::size_t>(m.sh_coeffs());
  const float scale = std::ldexp(1.0f, s.fractional_bits);
  const float flip[3] = {1, -1, -1};  // RDF -> RUB
  for (std::size_t i = 0; i < m.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      const auto fixed = static_cast<int32_t>(std::round(flip[a] * m.means[3 * i + a] * scale));
      for (int b = 0; b < 3; ++b) s.positions[9 * i + 3 * a + b] = static_cast<uint8_t>((fixed >> (8 * b)) & 0xff);
      s.scales[3 * i + a] = to_u8((m.log_scales[3 * i + a] + 10.0f) * 16.0f);
      s.colors[3 * i + a] = to_u8(m.sh[i * K * 3 + a] * kColorScale * 255.0f + 127.5f);
    }
    s.alphas[i] = to_u8(255.0f / (1.0f + std::exp(-m.opacity_logits[i])));
    pack_smallest_three(&m.rotations[4 * i], &s.rotations[4 * i]);
    for (std::size_t k = 1; k < K; ++k)
      for (std::size_t c = 0; c < 3; ++c)
        s.sh[(i * (K - 1) + k - 1) * 3 + c] = quantize_sh(kShFlip[k - 1] * m.sh[(i * K + k) * 3 + c], k < 4 ? 8 : 16);
  }
  return s;
}

std::vector<uint8_t> gzip(const std::vector<uint8_t>& in, const std::string& path) {
  z_stream z{};
  if (deflateInit2(&z, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY) != Z_OK)
    fail(path, "zlib deflateInit2 failed");
  std::vector<uint8_t> out(deflateBound(&z, static_cast<uLong>(in.size())));
  z.next_in = const_cast<Bytef*>(in.data());
  z.avail_in = static_cast<uInt>(in.size());
  z.next_out = out.data();
  z.avail_out = static_cast<uInt>(out.size());
  const int rc = deflate(&z, Z_FINISH);
  out.resize(z.total_out);
  deflateEnd(&z);
  if (rc != Z_STREAM_END) fail(path, "zlib deflate failed");
  return out;
}

// The 16 bytes both headers start with; `last` is the legacy reserved byte or the v4 stream count.
std::vector<uint8_t> header_start(const Streams& s, int last) {
  std::vector<uint8_t> out(16, 0);
  const uint32_t words[3] = {kMagic, s.version, s.count};
  std::memcpy(out.data(), words, 12);
  out[12] = static_cast<uint8_t>(s.sh_degree);
  out[13] = static_cast<uint8_t>(s.fractional_bits);
  out[15] = static_cast<uint8_t>(last);
  return out;
}

std::vector<uint8_t> encode_legacy(Streams& s, const std::string& path) {
  std::vector<uint8_t> body = header_start(s, 0);
  for (auto* slot : stream_slots(s)) body.insert(body.end(), slot->begin(), slot->end());
  return gzip(body, path);
}

std::vector<uint8_t> encode_ngsp(Streams& s, const std::string& path) {
  std::vector<uint8_t> out = header_start(s, 6);
  out.resize(32 + 6 * 16, 0);
  out[16] = 32;  // TOC offset (u32 LE): no extension records
  for (std::size_t k = 0; k < 6; ++k) {
    const std::vector<uint8_t>& plain = *stream_slots(s)[k];
    std::vector<uint8_t> packed(ZSTD_compressBound(plain.size()));
    const std::size_t n = ZSTD_compress(packed.data(), packed.size(), plain.data(), plain.size(), 12);
    if (ZSTD_isError(n)) fail(path, std::string("zstd compression failed: ") + ZSTD_getErrorName(n));
    const uint64_t sizes[2] = {n, plain.size()};
    std::memcpy(&out[32 + 16 * k], sizes, 16);
    out.insert(out.end(), packed.begin(), packed.begin() + static_cast<std::ptrdiff_t>(n));
  }
  return out;
}

}  // namespace

bool looks_like_spz(const std::vector<uint8_t>& head) {
  if (head.size() >= 4 && load<uint32_t>(head.data()) == kMagic) return true;
  return head.size() >= 2 && head[0] == 0x1f && head[1] == 0x8b;
}

GaussianModel read_spz(const std::string& path, const LoadProgress& progress) {
  const std::vector<uint8_t> file = read_all(path);
  if (!looks_like_spz(file)) fail(path, "not an .spz file (neither 'NGSP' nor gzip magic)");
  const Streams s = file[0] == 0x1f ? parse_legacy(file, path) : parse_ngsp(file, path);
  return to_model(s, progress);
}

void write_spz(const GaussianModel& model, const std::string& path, int version) {
  if (version != 3 && version != 4)
    fail(path, ".spz version " + std::to_string(version) + " cannot be written (3 or 4)");
  if (model.size() > 0xffffffffu) fail(path, "more than 2^32 - 1 Gaussians do not fit .spz");
  Streams s = from_model(model, version);
  const std::vector<uint8_t> bytes = version == 4 ? encode_ngsp(s, path) : encode_legacy(s, path);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) fail(path, "cannot open for writing");
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (!out) fail(path, "write failed");
}

}  // namespace catgs
