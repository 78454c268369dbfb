// SOG reader (layout, axes and losses in sog_file.h).
#include "scene/sog_file.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstring>

#include <nlohmann/json.hpp>

#ifdef CATGS_HAVE_SOG
#include <webp/decode.h>
#include <zip.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#endif

namespace catgs {

namespace {

bool json_object_start(const std::vector<uint8_t>& head) {
  auto first = std::find_if(head.begin(), head.end(), [](uint8_t c) { return !std::isspace(c); });
  return first != head.end() && *first == '{';
}

}  // namespace

bool looks_like_sog_zip(const std::vector<uint8_t>& head) {
  return head.size() >= 4 && std::memcmp(head.data(), "PK\x03\x04", 4) == 0;
}

bool looks_like_sog_meta(const std::vector<uint8_t>& head) {
  if (!json_object_start(head)) return false;
  const std::string text(head.begin(), head.end());
  return text.find("\"means\"") != std::string::npos && text.find("\"files\"") != std::string::npos;
}

#ifndef CATGS_HAVE_SOG

namespace {

[[noreturn]] void unsupported(const std::string& path) {
  throw SceneFileError(path, "this build has no SOG support (libwebp and libzip were not found at configure time)");
}

}  // namespace

bool sog_supported() { return false; }

SogSummary peek_sog(const std::string& path) { unsupported(path); }

GaussianModel read_sog(const std::string& path, const LoadProgress&) { unsupported(path); }

#else

namespace {

using nlohmann::json;

constexpr uint64_t kMaxGaussians = 1ull << 31;
// A corrupt or hostile archive must not make us allocate without bound: an entry may expand to at
// most 1024 times the archive's size (as the .spz reader caps gzip), and an image may hold at most
// 4x the texels it needs plus 1 Mi (the writer pads to multiples of 4 in both directions).
constexpr uint64_t kMaxExpansion = 1024;
constexpr uint64_t kSpareTexels = 1u << 20;
constexpr int kPaletteRow = 64;            // shN centroids: palette entries per image row
constexpr uint64_t kMaxPalette = 1 << 16;  // shN labels are 16 bits
constexpr float kSqrtHalf = 0.70710678118654752f;

[[noreturn]] void fail(const std::string& path, const std::string& problem) { throw SceneFileError(path, problem); }

// The files of one scene: entries of a zip archive, or files beside meta.json.
class SogFiles {
 public:
  explicit SogFiles(const std::string& path) : path_(path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) fail(path, "cannot open file");
    std::vector<uint8_t> head(4, 0);
    in.read(reinterpret_cast<char*>(head.data()), 4);
    head.resize(static_cast<std::size_t>(in.gcount()));
    if (looks_like_sog_zip(head)) open_zip();
  }
  ~SogFiles() {
    if (zip_) zip_discard(zip_);
  }
  SogFiles(const SogFiles&) = delete;
  SogFiles& operator=(const SogFiles&) = delete;

  std::string meta_text() const {
    const std::vector<uint8_t> bytes = zip_ ? read_entry("meta.json") : read_beside_meta("");
    return {bytes.begin(), bytes.end()};
  }
  // `name` as meta.json names it.
  std::vector<uint8_t> read(const std::string& name) const { return zip_ ? read_entry(name) : read_beside_meta(name); }

 private:
  void open_zip() {
    int code = 0;
    zip_ = zip_open(path_.c_str(), ZIP_RDONLY | ZIP_CHECKCONS, &code);
    if (!zip_) {
      zip_error_t error;
      zip_error_init_with_code(&error, code);
      const std::string what = zip_error_strerror(&error);
      zip_error_fini(&error);
      fail(path_, "not a readable zip archive (" + what + ")");
    }
    std::error_code ec;
    archive_size_ = std::filesystem::file_size(path_, ec);
  }

  std::vector<uint8_t> read_entry(const std::string& name) const {
    const zip_int64_t index = zip_name_locate(zip_, name.c_str(), 0);
    if (index < 0) fail(path_, "the archive has no entry '" + name + "'");
    zip_stat_t st;
    if (zip_stat_index(zip_, static_cast<zip_uint64_t>(index), 0, &st) != 0 || !(st.valid & ZIP_STAT_SIZE))
      fail(path_, "cannot read the size of archive entry '" + name + "'");
    if (st.size > kMaxExpansion * std::max<uint64_t>(archive_size_, 1))
      fail(path_, "archive entry '" + name + "' claims " + std::to_string(st.size) + " bytes, more than " +
                      std::to_string(kMaxExpansion) + "x the archive");
    zip_file_t* f = zip_fopen_index(zip_, static_cast<zip_uint64_t>(index), 0);
    if (!f) fail(path_, "cannot open archive entry '" + name + "': " + zip_strerror(zip_));
    std::vector<uint8_t> bytes(st.size);
    const zip_int64_t got = zip_fread(f, bytes.data(), st.size);
    // libzip checks the CRC when the entry's end is read: one more read must find the end.
    uint8_t past_end = 0;
    const zip_int64_t more = got < 0 ? -1 : zip_fread(f, &past_end, 1);
    const std::string why = got < 0 || more < 0 ? zip_file_strerror(f) : "its size disagrees with the directory";
    zip_fclose(f);
    if (got < 0 || more != 0 || static_cast<uint64_t>(got) != st.size)
      fail(path_, "corrupt archive entry '" + name + "' (" + why + ")");
    return bytes;
  }

  // "" is meta.json itself.
  std::vector<uint8_t> read_beside_meta(const std::string& name) const {
    const std::filesystem::path relative(name);
    for (const auto& part : relative)
      if (part == "..") fail(path_, "image name '" + name + "' leaves meta.json's folder");
    if (relative.is_absolute()) fail(path_, "image name '" + name + "' is absolute, not beside meta.json");
    const std::string file = name.empty() ? path_ : (std::filesystem::path(path_).parent_path() / relative).string();
    std::ifstream in(file, std::ios::binary);
    if (!in) fail(path_, name.empty() ? "cannot open file" : "cannot open image '" + name + "' (" + file + ")");
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  }

  std::string path_;
  zip_t* zip_ = nullptr;
  uint64_t archive_size_ = 0;
};

// An RGBA8 image, texel i at rgba[4 * i] (row-major).
struct Image {
  uint64_t width = 0, height = 0;
  std::vector<uint8_t> rgba;
  uint64_t texels() const { return width * height; }
  const uint8_t* texel(uint64_t i) const { return &rgba[4 * i]; }
};

// The header of a WebP image, required lossless: SOG stores numbers in its texels.
WebPBitstreamFeatures lossless_webp(const std::vector<uint8_t>& bytes, const std::string& name,
                                    const std::string& path) {
  WebPBitstreamFeatures features;
  if (WebPGetFeatures(bytes.data(), bytes.size(), &features) != VP8_STATUS_OK)
    fail(path, "image '" + name + "' is not a WebP image");
  if (features.format != 2)
    fail(path, "image '" + name + "' is not lossless WebP (SOG stores numbers in its texels; lossy codes alter them)");
  return features;
}

// Decodes `name` after checking it holds at least `needed` texels (and not absurdly more: a few
// bytes of lossless WebP can declare 16383 x 16383). `what` says what needs them.
Image load_image(const SogFiles& files, const std::string& name, uint64_t needed, const std::string& what,
                 const std::string& path) {
  const std::vector<uint8_t> bytes = files.read(name);
  const WebPBitstreamFeatures features = lossless_webp(bytes, name, path);
  Image im{static_cast<uint64_t>(features.width), static_cast<uint64_t>(features.height), {}};
  const std::string size = std::to_string(im.width) + " x " + std::to_string(im.height);
  if (im.texels() < needed) fail(path, "image '" + name + "' is " + size + ", too small for " + what);
  if (im.texels() > 4 * needed + kSpareTexels)
    fail(path, "image '" + name + "' is " + size + ", far larger than " + what + " need");
  im.rgba.resize(4 * im.texels());
  if (!WebPDecodeRGBAInto(bytes.data(), bytes.size(), im.rgba.data(), im.rgba.size(), features.width * 4))
    fail(path, "image '" + name + "' is corrupt WebP");
  return im;
}

// Byte -> value: a version 2 codebook, or a version 1 linear range made into one.
using Table = std::vector<float>;

Table linear_table(double min, double max) {
  Table t(256);
  for (int b = 0; b < 256; ++b) t[static_cast<std::size_t>(b)] = static_cast<float>(min + (max - min) * (b / 255.0));
  return t;
}

// Opacity logit of sigmoid(opacity) * 255, the value version 2 writes.
Table alpha_table() {
  Table t(256);
  t[0] = -kOpacityLogitLimit;
  t[255] = kOpacityLogitLimit;
  for (int b = 1; b < 255; ++b) {
    const float a = static_cast<float>(b);
    t[static_cast<std::size_t>(b)] = std::log(a / (255.0f - a));
  }
  return t;
}

// Everything meta.json says, in one form for both versions.
struct Plan {
  uint64_t count = 0;
  std::array<std::string, 2> means_files;
  std::array<double, 3> means_min{}, means_max{};
  std::string quats_file, scales_file, sh0_file;
  std::array<Table, 3> scales;
  std::array<Table, 4> sh0;  // DC r, g, b; opacity logit
  bool has_shn = false;
  int bands = -1;                        // -1: from the centroid image's width (version 1)
  uint64_t palette = 0;                  // 0: 64 a row of the centroid image (version 1)
  std::array<std::string, 2> shn_files;  // centroids, labels
  Table sh_rest;
};

// meta.json's fields, each checked before use; errors name the field ("means.mins").
class Meta {
 public:
  Meta(const json& root, const std::string& path) : root_(root), path_(path) {}

  const json& at(const std::string& dotted) const {
    const json* j = &root_;
    std::size_t from = 0;
    while (true) {
      const std::size_t dot = dotted.find('.', from);
      const std::string key = dotted.substr(from, dot == std::string::npos ? std::string::npos : dot - from);
      if (!j->is_object() || !j->contains(key)) fail(path_, "meta.json lacks '" + dotted + "'");
      j = &j->at(key);
      if (dot == std::string::npos) return *j;
      from = dot + 1;
    }
  }
  bool has(const std::string& key) const { return root_.contains(key); }

  double number(const json& v, const std::string& name) const {
    if (!v.is_number() || !std::isfinite(v.get<double>()))
      fail(path_, "meta.json '" + name + "' is not a finite number");
    return v.get<double>();
  }
  double number(const std::string& dotted) const { return number(at(dotted), dotted); }

  uint64_t whole(const json& v, const std::string& name, uint64_t min, uint64_t max) const {
    if (!v.is_number_unsigned() || v.get<uint64_t>() < min || v.get<uint64_t>() > max)
      fail(path_,
           "meta.json '" + name + "' must be a whole number in " + std::to_string(min) + ".." + std::to_string(max));
    return v.get<uint64_t>();
  }
  uint64_t whole(const std::string& dotted, uint64_t min, uint64_t max) const {
    return whole(at(dotted), dotted, min, max);
  }

  std::vector<double> numbers(const std::string& dotted, std::size_t min_size, std::size_t max_size) const {
    const json& v = at(dotted);
    if (!v.is_array() || v.size() < min_size || v.size() > max_size)
      fail(path_, "meta.json '" + dotted + "' must be an array of " + std::to_string(min_size) +
                      (min_size == max_size ? "" : ".." + std::to_string(max_size)) + " numbers");
    std::vector<double> out;
    for (const json& x : v) out.push_back(number(x, dotted));
    return out;
  }

  Table codebook(const std::string& dotted) const {
    const std::vector<double> v = numbers(dotted, 1, 256);
    return Table(v.begin(), v.end());
  }

  std::string file(const std::string& section, std::size_t k) const {
    const json& files = at(section + ".files");
    const std::string name = section + ".files[" + std::to_string(k) + "]";
    if (!files.is_array() || files.size() <= k || !files[k].is_string() || files[k].get<std::string>().empty())
      fail(path_, "meta.json '" + name + "' is not a file name");
    return files[k].get<std::string>();
  }

 private:
  const json& root_;
  const std::string& path_;
};

void plan_means(const Meta& meta, Plan& p) {
  const auto mins = meta.numbers("means.mins", 3, 3), maxs = meta.numbers("means.maxs", 3, 3);
  std::copy(mins.begin(), mins.end(), p.means_min.begin());
  std::copy(maxs.begin(), maxs.end(), p.means_max.begin());
  p.means_files = {meta.file("means", 0), meta.file("means", 1)};
  p.quats_file = meta.file("quats", 0);
  p.scales_file = meta.file("scales", 0);
  p.sh0_file = meta.file("sh0", 0);
}

Plan plan_v2(const Meta& meta) {
  Plan p;
  p.count = meta.whole("count", 1, kMaxGaussians);
  plan_means(meta, p);
  const Table scales = meta.codebook("scales.codebook"), colours = meta.codebook("sh0.codebook");
  p.scales = {scales, scales, scales};
  p.sh0 = {colours, colours, colours, alpha_table()};
  if (meta.has("shN")) {
    p.has_shn = true;
    p.bands = static_cast<int>(meta.whole("shN.bands", 0, kMaxShDegree));
    p.palette = meta.whole("shN.count", 1, kMaxPalette);
    p.sh_rest = meta.codebook("shN.codebook");
    p.shn_files = {meta.file("shN", 0), meta.file("shN", 1)};
  }
  return p;
}

Plan plan_v1(const Meta& meta, const std::string& path) {
  Plan p;
  const json& shape = meta.at("means.shape");
  if (!shape.is_array() || shape.empty()) fail(path, "meta.json 'means.shape' must be an array [count, 3]");
  p.count = meta.whole(shape[0], "means.shape[0]", 1, kMaxGaussians);
  plan_means(meta, p);
  const auto s_min = meta.numbers("scales.mins", 3, 3), s_max = meta.numbers("scales.maxs", 3, 3);
  for (std::size_t a = 0; a < 3; ++a) p.scales[a] = linear_table(s_min[a], s_max[a]);
  const auto c_min = meta.numbers("sh0.mins", 4, 4), c_max = meta.numbers("sh0.maxs", 4, 4);
  for (std::size_t a = 0; a < 4; ++a) p.sh0[a] = linear_table(c_min[a], c_max[a]);
  if (meta.has("shN")) {
    p.has_shn = true;
    p.sh_rest = linear_table(meta.number("shN.mins"), meta.number("shN.maxs"));
    p.shn_files = {meta.file("shN", 0), meta.file("shN", 1)};
  }
  return p;
}

json parse_meta(const SogFiles& files, const std::string& path) {
  const json root = json::parse(files.meta_text(), nullptr, false);
  if (root.is_discarded() || !root.is_object()) fail(path, "meta.json is not a JSON object");
  return root;
}

// Version 2, or 1 when the key is absent (splat-transform's rule).
int meta_version(const json& root, const std::string& path) {
  if (!root.contains("version")) return 1;
  const json& v = root.at("version");
  if (!v.is_number_integer() || v.get<int64_t>() != 2)
    fail(path, "unsupported SOG version " + v.dump() + " (1 and 2 are read)");
  return 2;
}

float lookup(const Table& t, uint8_t byte, const char* what, uint64_t i, const std::string& path) {
  if (byte >= t.size())
    fail(path, std::string(what) + " of Gaussian " + std::to_string(i) + " indexes entry " + std::to_string(byte) +
                   " of a " + std::to_string(t.size()) + "-entry codebook");
  return t[byte];
}

// Inverse of the writer's log transform v = sign(x) * ln(|x| + 1).
float inverse_log_transform(double v) {
  const double x = std::exp(std::fabs(v)) - 1.0;
  return static_cast<float>(v < 0 ? -x : x);
}

void decode_means(const Plan& p, const Image& lo, const Image& hi, GaussianModel& m) {
  for (uint64_t i = 0; i < p.count; ++i)
    for (int a = 0; a < 3; ++a) {
      const unsigned u = lo.texel(i)[a] | (hi.texel(i)[a] << 8);
      const double range = p.means_max[a] - p.means_min[a];
      m.means[3 * i + a] = inverse_log_transform(p.means_min[a] + (range == 0 ? 1.0 : range) * (u / 65535.0));
    }
}

// Smallest three of (w, x, y, z), the largest's index in alpha as 252 + index.
void decode_quats(const Image& q, uint64_t count, GaussianModel& m) {
  for (uint64_t i = 0; i < count; ++i) {
    const uint8_t* t = q.texel(i);
    float* wxyz = &m.rotations[4 * i];
    if (t[3] < 252) {  // not a quaternion: identity, as splat-transform reads it
      wxyz[0] = 1.0f;
      continue;
    }
    const unsigned largest = t[3] - 252u;
    float sum = 0;
    for (unsigned k = 0, s = 0; k < 4; ++k) {
      if (k == largest) continue;
      wxyz[k] = (static_cast<float>(t[s++]) / 255.0f * 2.0f - 1.0f) * kSqrtHalf;
      sum += wxyz[k] * wxyz[k];
    }
    wxyz[largest] = std::sqrt(std::max(0.0f, 1.0f - sum));
  }
}

void decode_scales_and_colours(const Plan& p, const Image& scales, const Image& sh0, GaussianModel& m,
                               const std::string& path) {
  const std::size_t K = static_cast<std::size_t>(m.sh_coeffs());
  for (uint64_t i = 0; i < p.count; ++i) {
    for (std::size_t a = 0; a < 3; ++a) {
      m.log_scales[3 * i + a] = lookup(p.scales[a], scales.texel(i)[a], "scale", i, path);
      m.sh[i * K * 3 + a] = lookup(p.sh0[a], sh0.texel(i)[a], "colour", i, path);
    }
    m.opacity_logits[i] = lookup(p.sh0[3], sh0.texel(i)[3], "opacity", i, path);
  }
}

// SH coefficients 1..K-1 from each Gaussian's palette entry.
void decode_sh_rest(const Plan& p, const Image& centroids, const Image& labels, GaussianModel& m,
                    const std::string& path) {
  const uint64_t C = static_cast<uint64_t>(m.sh_coeffs() - 1);
  const std::size_t K = static_cast<std::size_t>(m.sh_coeffs());
  for (uint64_t i = 0; i < p.count; ++i) {
    const uint64_t label = labels.texel(i)[0] | (labels.texel(i)[1] << 8);
    if (label >= p.palette)
      fail(path, "shN label " + std::to_string(label) + " of Gaussian " + std::to_string(i) + " is past the " +
                     std::to_string(p.palette) + "-entry palette");
    const uint64_t row = label / kPaletteRow, first = (label % kPaletteRow) * C;
    for (uint64_t j = 0; j < C; ++j) {
      const uint8_t* t = centroids.texel(row * centroids.width + first + j);
      for (std::size_t c = 0; c < 3; ++c) m.sh[(i * K + 1 + j) * 3 + c] = lookup(p.sh_rest, t[c], "SH", i, path);
    }
  }
}

// SH rest coefficients per channel for bands 0..3.
constexpr std::array<uint64_t, 4> kRestCoeffs = {0, 3, 8, 15};

struct ShImages {
  Image centroids, labels;
};

// Version 1 names neither the bands nor the palette size: the centroid image's width gives the
// bands (64 entries a row), its height the palette.
void plan_v1_palette(const std::vector<uint8_t>& centroids, Plan& p, const std::string& path) {
  const WebPBitstreamFeatures f = lossless_webp(centroids, p.shn_files[0], path);
  const auto width = static_cast<uint64_t>(f.width);
  const auto it = std::find(kRestCoeffs.begin() + 1, kRestCoeffs.end(), width / kPaletteRow);
  if (width % kPaletteRow != 0 || it == kRestCoeffs.end())
    fail(path, "shN centroid image '" + p.shn_files[0] + "' is " + std::to_string(width) +
                   " wide, not 192, 512 or 960 (SH bands 1-3)");
  p.bands = static_cast<int>(it - kRestCoeffs.begin());
  p.palette = std::min<uint64_t>(kMaxPalette, static_cast<uint64_t>(f.height) * kPaletteRow);
}

// shN's two images, once the bands are known; none for 0 bands.
std::optional<ShImages> load_sh_rest(const SogFiles& files, Plan& p, const std::string& path) {
  if (p.bands < 0) plan_v1_palette(files.read(p.shn_files[0]), p, path);
  if (p.bands == 0) return std::nullopt;
  const uint64_t C = kRestCoeffs[static_cast<std::size_t>(p.bands)];
  const uint64_t rows = (p.palette + kPaletteRow - 1) / kPaletteRow;
  ShImages sh{
      load_image(files, p.shn_files[0], rows * kPaletteRow * C, std::to_string(p.palette) + " palette entries", path),
      load_image(files, p.shn_files[1], p.count, std::to_string(p.count) + " Gaussians", path)};
  if (sh.centroids.width != kPaletteRow * C)
    fail(path, "shN centroid image '" + p.shn_files[0] + "' is " + std::to_string(sh.centroids.width) + " wide; " +
                   std::to_string(p.bands) + " SH bands need " + std::to_string(kPaletteRow * C));
  return sh;
}

GaussianModel decode(const SogFiles& files, Plan p, const std::string& path) {
  const std::optional<ShImages> sh = p.has_shn ? load_sh_rest(files, p, path) : std::nullopt;
  const std::string what = std::to_string(p.count) + " Gaussians";
  const Image lo = load_image(files, p.means_files[0], p.count, what, path);
  const Image hi = load_image(files, p.means_files[1], p.count, what, path);
  GaussianModel m;
  m.sh_degree = std::max(p.bands, 0);
  m.resize(p.count);
  decode_means(p, lo, hi, m);
  decode_quats(load_image(files, p.quats_file, p.count, what, path), p.count, m);
  decode_scales_and_colours(p, load_image(files, p.scales_file, p.count, what, path),
                            load_image(files, p.sh0_file, p.count, what, path), m, path);
  if (sh) decode_sh_rest(p, sh->centroids, sh->labels, m, path);
  return m;
}

}  // namespace

bool sog_supported() { return true; }

SogSummary peek_sog(const std::string& path) {
  const SogFiles files(path);
  const json root = parse_meta(files, path);
  const Meta meta(root, path);
  SogSummary s;
  if (meta_version(root, path) == 2) {
    s.gaussians = meta.whole("count", 1, kMaxGaussians);
    s.sh_degree = root.contains("shN") ? static_cast<int>(meta.whole("shN.bands", 0, kMaxShDegree)) : 0;
  } else {
    s.gaussians = plan_v1(meta, path).count;
    if (!root.contains("shN")) s.sh_degree = 0;  // else the centroid image's width says
  }
  return s;
}

GaussianModel read_sog(const std::string& path, const LoadProgress& progress) {
  const SogFiles files(path);
  const json root = parse_meta(files, path);
  const Meta meta(root, path);
  GaussianModel m = decode(files, meta_version(root, path) == 2 ? plan_v2(meta) : plan_v1(meta, path), path);
  if (progress) progress(m.size(), m.size());  // its images decode whole: no steps between
  return m;
}

#endif  // CATGS_HAVE_SOG

}  // namespace catgs
