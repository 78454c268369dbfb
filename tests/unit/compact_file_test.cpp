// The compact scene (scene/compact_file.h), against the float scene it was written from: every
// value within the steps its header documents (bounds worked out here from the float model, not
// by the writer), its bytes where the layout says, the picture of real scenes, and the checks a
// damaged or forged file meets.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <map>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "common/image_io.h"
#include "forward_model/lod.h"
#include "lod/lod_build.h"
#include "renderer/renderer.h"
#include "scene/compact_file.h"
#include "scene/format_detect.h"
#include "scene/morton.h"
#include "scene/ply_io.h"
#include "scene/scene_cache.h"
#include "scene/scene_peek.h"
#include "small_city.h"
#include "test_data.h"

namespace catgs {
namespace {

namespace fs = std::filesystem;

float sigmoid(float x) { return 1.0f / (1.0f + std::exp(-x)); }

// The rotation's angle between two quaternions (w, x, y, z), radians; q and -q are the same.
double rotation_angle(const float* a, const float* b) {
  double dot = 0, na = 0, nb = 0;
  for (int k = 0; k < 4; ++k) dot += double(a[k]) * b[k], na += double(a[k]) * a[k], nb += double(b[k]) * b[k];
  return 2.0 * std::acos(std::min(1.0, std::fabs(dot) / std::sqrt(na * nb)));
}

// Every Gaussian of `got` (the file's) against `want` (the float model written), chunk by chunk,
// within the steps compact_file.h documents, the ranges taken here from `want`.
void expect_within_steps(const GaussianModel& got, const GaussianModel& want) {
  ASSERT_EQ(got.size(), want.size());
  ASSERT_EQ(got.sh_degree, want.sh_degree);
  const int K = want.sh_coeffs();
  const auto band = [](int k) { return k < 4 ? 0 : k < 9 ? 1 : 2; };
  std::size_t worst_rotation = 0;
  double worst_angle = 0;
  for (std::size_t c = 0; c * 256 < want.size(); ++c) {
    const std::size_t end = std::min(want.size(), (c + 1) * 256);
    float lo[3][3], hi[3][3], bound[3] = {0, 0, 0};  // position, log scale, DC
    for (int f = 0; f < 3; ++f) std::fill_n(lo[f], 3, INFINITY), std::fill_n(hi[f], 3, -INFINITY);
    for (std::size_t i = c * 256; i < end; ++i) {
      for (int a = 0; a < 3; ++a) {
        const float v[3] = {want.means[3 * i + a], want.log_scales[3 * i + a], want.sh[i * K * 3 + a]};
        for (int f = 0; f < 3; ++f) lo[f][a] = std::min(lo[f][a], v[f]), hi[f][a] = std::max(hi[f][a], v[f]);
      }
      for (int k = 1; k < K; ++k)
        for (int ch = 0; ch < 3; ++ch)
          bound[band(k)] = std::max(bound[band(k)], std::fabs(want.sh[(i * K + k) * 3 + ch]));
    }
    for (std::size_t i = c * 256; i < end; ++i) {
      for (int a = 0; a < 3; ++a) {
        // Half a step, and a few float ulps of the range for the decode's own rounding.
        auto near = [](float g, float w, float step, float lo_, float hi_) {
          const float slack = 4e-7f * std::max(std::fabs(lo_), std::fabs(hi_)) + 1e-30f;
          return std::fabs(g - w) <= 0.5f * step + slack;
        };
        const float pos_step = (hi[0][a] - lo[0][a]) / 65535.0f;
        const float scale_step = (hi[1][a] - lo[1][a]) / (a == 1 ? 1023.0f : 2047.0f);
        const float dc_step = (hi[2][a] - lo[2][a]) / 255.0f;
        ASSERT_TRUE(near(got.means[3 * i + a], want.means[3 * i + a], pos_step, lo[0][a], hi[0][a]))
            << "mean of Gaussian " << i << " axis " << a << ": " << got.means[3 * i + a] << " vs "
            << want.means[3 * i + a];
        ASSERT_TRUE(near(got.log_scales[3 * i + a], want.log_scales[3 * i + a], scale_step, lo[1][a], hi[1][a]))
            << "log scale of Gaussian " << i;
        ASSERT_TRUE(near(got.sh[i * K * 3 + a], want.sh[i * K * 3 + a], dc_step, lo[2][a], hi[2][a]))
            << "DC of Gaussian " << i;
      }
      ASSERT_LE(std::fabs(sigmoid(got.opacity_logits[i]) - sigmoid(want.opacity_logits[i])), 0.5f / 255.0f + 1e-6f)
          << "opacity of Gaussian " << i;
      for (int k = 1; k < K; ++k)
        for (int ch = 0; ch < 3; ++ch)
          ASSERT_LE(std::fabs(got.sh[(i * K + k) * 3 + ch] - want.sh[(i * K + k) * 3 + ch]),
                    bound[band(k)] / 126.0f * (1.0f + 1e-4f))
              << "SH coefficient " << k << " of Gaussian " << i;
      const double angle = rotation_angle(&got.rotations[4 * i], &want.rotations[4 * i]);
      if (angle > worst_angle) worst_angle = angle, worst_rotation = i;
    }
  }
  // Each of three components within sqrt(2) / 2046 of its value: a few thousandths of a radian.
  EXPECT_LE(worst_angle, 0.005) << "rotation of Gaussian " << worst_rotation;
}

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}
void write_bytes(const std::string& path, const std::string& bytes) { std::ofstream(path, std::ios::binary) << bytes; }

TEST(CompactScene, EveryValueWithinItsDocumentedStep) {
  CATGS_REQUIRE_DATA(tumblewood, "scenes/tumblewood_sh2.ply");
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  const std::string dir = test::temp_dir();
  // SH degrees 2 (with its level of detail), 3 and 0 (plain scenes in Morton order).
  const GaussianModel tw = build_lod(load_scene(tumblewood));
  const GaussianModel fl = load_scene(flowers);
  const GaussianModel bk = load_scene(test::bundled_scene());
  for (const GaussianModel* m : {&tw, &fl, &bk}) {
    const GaussianModel want = m->lod.empty() ? permuted(*m, morton_order(*m)) : *m;
    const std::string out = dir + "/" + want.name + ".catgs";
    write_compact_scene(want, out);
    EXPECT_EQ(detect_scene_format(out), SceneFormat::compact);
    const GaussianModel got = load_scene(out);  // by its magic
    SCOPED_TRACE(want.name);
    EXPECT_EQ(got.name, want.name);
    expect_within_steps(got, want);
    ASSERT_EQ(got.lod.size(), want.lod.size());
    EXPECT_EQ(std::memcmp(got.lod.data(), want.lod.data(), got.lod.size() * sizeof(fm::LodNode)), 0);
    const double bytes_per_gaussian = double(fs::file_size(out)) / double(want.size());
    if (want.sh_degree == 2) {
      EXPECT_LE(bytes_per_gaussian, 40.0) << "issue 74: at most 40 bytes a Gaussian";
    }
    EXPECT_LE(bytes_per_gaussian, double(compact_record_bytes(want.sh_degree)) + 1.0);
    const ScenePeek peek = peek_scene(out);
    EXPECT_EQ(peek.format, "catgs");
    EXPECT_EQ(peek.gaussians.value_or(0), want.size());
    EXPECT_EQ(peek.sh_degree.value_or(-1), want.sh_degree);
    // In memory, exactly what the file gives.
    GaussianModel q = want;
    quantize_compact(q);
    test::expect_same_gaussians(got, q);
    // The codes the CUDA core keeps, with the file's bytes and the floats' fingerprints.
    ASSERT_TRUE(got.codes && q.codes);
    EXPECT_TRUE(compact_codes_match(got));
    EXPECT_TRUE(compact_codes_match(q));
    EXPECT_EQ(got.codes->rotation, q.codes->rotation);
    EXPECT_EQ(got.codes->sh, q.codes->sh);
    GaussianModel changed = got;
    changed.opacity_logits.back() += 1.0f;  // a change the codes do not carry
    EXPECT_FALSE(compact_codes_match(changed));
    // Written again (the server quantizes its LOD, serves it, then writes it), the file gives
    // back exactly what was served.
    const std::string again = dir + "/" + want.name + "_again.catgs";
    write_compact_scene(q, again);
    test::expect_same_gaussians(load_scene(again), q);
  }
}

// The bytes where compact_file.h's layout puts them, read here from the file by that text alone.
TEST(CompactScene, BytesLieWhereTheLayoutSays) {
  GaussianModel m;
  m.name = "three";
  m.sh_degree = 1;
  m.resize(3);
  const float means[9] = {0, 0, 0, 1, 2, 4, 0.25f, 1, 3};
  std::copy_n(means, 9, m.means.begin());
  for (std::size_t i = 0; i < 3; ++i) {
    m.rotations[4 * i] = 1.0f;
    m.opacity_logits[i] = 0.0f;  // alpha 0.5: q 128
    for (int a = 0; a < 3; ++a) m.log_scales[3 * i + a] = -2.0f - float(i);
  }
  m.sh[1 * 12 + 3] = 0.5f;  // Gaussian 1, coefficient 1, red: the band's bound
  const std::string path = test::temp_dir() + "/three.catgs";
  write_compact_scene(m, path);
  const std::string b = read_bytes(path);
  ASSERT_EQ(b.substr(0, 8), "CATGSCMP");
  // Header 256 bytes, one chunk's ranges (84), no LOD, one block hash (8): data at 4096.
  const uint64_t record = 18 + (7 * 9 + 7) / 8;
  EXPECT_EQ(compact_record_bytes(1), record);
  ASSERT_EQ(b.size(), 4096 + 3 * record);
  float ranges[21];
  std::memcpy(ranges, b.data() + 256, sizeof ranges);
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(ranges[a], std::min({means[a], means[3 + a], means[6 + a]}));
    EXPECT_EQ(ranges[3 + a], std::max({means[a], means[3 + a], means[6 + a]}));
    EXPECT_EQ(ranges[6 + a], -4.0f);  // log scales
    EXPECT_EQ(ranges[9 + a], -2.0f);
  }
  EXPECT_EQ(ranges[18], 0.5f);  // band 1's bound
  const char* data = b.data() + 4096;
  uint16_t pos[3];
  std::memcpy(pos, data + 6 * 2, 6);  // Gaussian 2's position
  EXPECT_EQ(pos[0], std::lround(0.25 * 65535));
  EXPECT_EQ(pos[1], std::lround(1.0 / 2.0 * 65535));
  EXPECT_EQ(pos[2], std::lround(3.0 / 4.0 * 65535));
  uint32_t rot, scale;
  std::memcpy(&rot, data + 18 + 4 * 0, 4);    // Gaussian 0's rotation: identity, w (index 0) largest
  std::memcpy(&scale, data + 30 + 4 * 1, 4);  // Gaussian 1's log scales: -3 in [-4, -2], the middle
  EXPECT_EQ(rot >> 30, 0u);
  EXPECT_EQ((rot >> 20) & 1023u, 512u);  // 0 -> 0.5 of [-1/sqrt(2), 1/sqrt(2)]: 511.5 rounds up
  EXPECT_EQ(scale >> 21, 1024u);         // 0.5 of 2047 rounds to 1024
  EXPECT_EQ((scale >> 11) & 1023u, 512u);
  const auto* colour = reinterpret_cast<const uint8_t*>(data + 42);
  EXPECT_EQ(colour[4 * 1 + 3], 128);  // alpha 0.5
  // Gaussian 1's SH rest: 7-bit codes LSB first; its first (coefficient 1, red) is 0.5 of a bound
  // 0.5: q = 63 + 63 = 126; every other is 0: q = 63.
  const auto* sh = reinterpret_cast<const uint8_t*>(data + 54 + 8 * 1);
  EXPECT_EQ(sh[0] & 0x7f, 126);
  EXPECT_EQ(((sh[0] >> 7) | (sh[1] << 1)) & 0x7f, 63);
}

// A SuperSplat compressed PLY as written: its chunk rows (float ranges by name) and each vertex's
// packed words, read here from the PLY header alone (binary little endian), not by ply_io.
struct CompressedPlyCodes {
  std::vector<std::map<std::string, float>> chunks;
  std::vector<std::array<uint32_t, 4>> packed;  // position, rotation, scale, colour
  std::vector<std::vector<uint8_t>> sh;         // per vertex its f_rest_* bytes (INRIA order), if any
};
CompressedPlyCodes read_compressed_codes(const std::string& path) {
  const std::string bytes = read_bytes(path);
  const std::size_t body = bytes.find("end_header\n") + 11;
  std::istringstream header(bytes.substr(0, body));
  struct Element {
    std::string name;
    std::size_t count = 0;
    std::vector<std::pair<std::string, std::string>> properties;  // type, name
  };
  std::vector<Element> elements;
  for (std::string line; std::getline(header, line);) {
    std::istringstream words(line);
    std::string word, a, b;
    words >> word >> a >> b;
    if (word == "element") elements.push_back({a, std::stoul(b), {}});
    if (word == "property") elements.back().properties.emplace_back(a, b);
  }
  const auto width = [](const std::string& type) { return type == "uchar" || type == "uint8" ? 1u : 4u; };
  CompressedPlyCodes out;
  std::size_t at = body;
  for (const Element& e : elements) {
    for (std::size_t row = 0; row < e.count; ++row) {
      std::map<std::string, float> chunk;
      std::array<uint32_t, 4> packed{};
      std::vector<uint8_t> rest;
      for (const auto& [type, name] : e.properties) {
        uint32_t word = 0;
        std::memcpy(&word, bytes.data() + at, width(type));
        at += width(type);
        if (e.name == "chunk") std::memcpy(&chunk[name], &word, 4);
        if (e.name == "sh") rest.push_back(static_cast<uint8_t>(word));
        const char* kPacked[4] = {"packed_position", "packed_rotation", "packed_scale", "packed_color"};
        for (int k = 0; k < 4; ++k)
          if (e.name == "vertex" && name == kPacked[k]) packed[k] = word;
      }
      if (e.name == "chunk") out.chunks.push_back(chunk);
      if (e.name == "vertex") out.packed.push_back(packed);
      if (e.name == "sh") out.sh.push_back(rest);
    }
  }
  return out;
}

// Issue 74: a compressed PLY source loses nothing it had. Quantized in its own order (as
// `catgs-scene convert` keeps a compressed PLY's), each compact chunk's ranges lie within the
// source chunk's and its steps are no coarser, so every code the source held is recovered from
// the compact decode: rounding each decoded value back onto the source's own grid (its chunk's
// min/max and bit width, read from the file here) gives the source's code, and the rotation codes
// are the source's words. The SH rest's 8-bit buckets of [-4, 4] come back too while a chunk's
// band bound stays under about 2 (the compact keeps 7 bits of it): no code was lost here. The real
// compressed PLYs in the data (SH degree 0), and the real SH degree 2 scene written as compressed
// PLY by write_compressed_ply (Morton order, as catgs-scene compact writes it).
TEST(CompactScene, CompressedPlySourceKeepsEveryCode) {
  CATGS_REQUIRE_DATA(guitar, "scenes/guitar.compressed.ply");
  CATGS_REQUIRE_DATA(tumblewood, "scenes/tumblewood_sh2.ply");
  const GaussianModel tw = load_scene(tumblewood);
  const std::string tw_compressed = test::temp_dir() + "/tumblewood_sh2.compressed.ply";
  write_compressed_ply(permuted(tw, morton_order(tw)), tw_compressed);
  for (const std::string& path : {test::bundled_scene(), guitar, tw_compressed}) {
    SCOPED_TRACE(path);
    const CompressedPlyCodes source = read_compressed_codes(path);
    const GaussianModel m = load_scene(path);
    ASSERT_EQ(source.packed.size(), m.size());
    ASSERT_EQ(source.chunks.size(), fm::chunk_count(m.size()));
    ASSERT_EQ(source.sh.size(), m.sh_degree > 0 ? m.size() : 0u);
    // The code of v on [lo, hi] in `bits` bits, as the source's writer rounds it.
    const auto code = [](float v, float lo, float hi, int bits) {
      const double top = double((1u << bits) - 1);
      return hi > lo ? uint32_t(std::lround(std::clamp((double(v) - lo) / (double(hi) - lo), 0.0, 1.0) * top)) : 0u;
    };
    const int shift[3] = {21, 11, 0}, bits[3] = {11, 10, 11};
    const char* axis[3] = {"x", "y", "z"};
    const char* channel[3] = {"r", "g", "b"};
    // The source's codes against q's first m.size() Gaussians (q quantized: the scene, or a LOD
    // built from it whose leaves keep its order).
    const auto expect_every_code = [&](const GaussianModel& q) {
      ASSERT_TRUE(q.codes);
      std::size_t checked = 0, sh_checked = 0, lost[6] = {};  // position, scale, colour, alpha, rotation, SH rest
      for (std::size_t i = 0; i < m.size(); ++i) {
        const std::map<std::string, float>& c = source.chunks[i / 256];
        const std::array<uint32_t, 4>& p = source.packed[i];
        for (int a = 0; a < 3; ++a) {
          const uint32_t mask = (1u << bits[a]) - 1u, want_pos = (p[0] >> shift[a]) & mask;
          const std::string x = axis[a];
          if (c.at("max_" + x) > c.at("min_" + x))
            lost[0] += code(q.means[3 * i + a], c.at("min_" + x), c.at("max_" + x), bits[a]) != want_pos;
          const uint32_t want_scale = (p[2] >> shift[a]) & mask;
          if (c.at("max_scale_" + x) > c.at("min_scale_" + x))
            lost[1] +=
                code(q.log_scales[3 * i + a], c.at("min_scale_" + x), c.at("max_scale_" + x), bits[a]) != want_scale;
          const std::string ch = channel[a];
          const float lo = c.count("min_" + ch) ? c.at("min_" + ch) : 0.0f;
          const float hi = c.count("max_" + ch) ? c.at("max_" + ch) : 1.0f;
          const float colour = 0.5f + 0.28209479177387814f * q.sh[3 * i * q.sh_coeffs() + a];
          lost[2] += code(colour, lo, hi, 8) != ((p[3] >> (24 - 8 * a)) & 255u);
        }
        lost[3] += code(sigmoid(q.opacity_logits[i]), 0.0f, 1.0f, 8) != (p[3] & 255u);
        const int rest = q.sh_coeffs() - 1;
        for (std::size_t j = 0; i < source.sh.size() && j < source.sh[i].size(); ++j) {
          const float v = q.sh[(i * q.sh_coeffs() + 1 + j % rest) * 3 + j / rest];  // f_rest[c * rest + k - 1]
          lost[5] += std::clamp(std::lround(std::floor((double(v) + 4.0) * 32.0)), 0l, 255l) != source.sh[i][j];
          ++sh_checked;
        }
        lost[4] += q.codes->rotation[i] != p[1];  // the same smallest-three packing (quantize.h)
        ++checked;
      }
      EXPECT_EQ(checked, m.size());
      EXPECT_EQ(lost[0], 0u) << "position codes not recovered";
      EXPECT_EQ(lost[1], 0u) << "log-scale codes not recovered";
      EXPECT_EQ(lost[2], 0u) << "colour codes not recovered";
      EXPECT_EQ(lost[3], 0u) << "alpha codes not recovered";
      EXPECT_EQ(lost[4], 0u) << "rotation codes changed";
      EXPECT_EQ(lost[5], 0u) << "SH rest codes not recovered";
      EXPECT_EQ(sh_checked, m.size() * std::size_t(3 * (m.sh_coeffs() - 1)));
    };
    GaussianModel q = m;
    quantize_compact(q);
    expect_every_code(q);
    {
      // A level of detail built with the source's order (catgs-scene lod and the server do so for
      // a compressed PLY): its leaves are the source's chunks and keep every code too.
      SCOPED_TRACE("LOD");
      LodBuildOptions keep;
      keep.keep_order = true;
      GaussianModel lod = build_lod(m, keep);
      ASSERT_GE(lod.size(), m.size());
      quantize_compact(lod);
      expect_every_code(lod);
    }
    // Re-sorted first (Morton order, as convert does a plain scene), a chunk mixes the source's
    // grids and codes are lost: why convert keeps a compressed PLY's order.
    const std::vector<uint32_t> order = morton_order(m);
    GaussianModel resorted = permuted(m, order);
    quantize_compact(resorted);
    std::size_t moved = 0;
    for (std::size_t k = 0; k < m.size(); ++k) {
      const std::size_t i = order[k];
      const std::map<std::string, float>& c = source.chunks[i / 256];
      if (c.at("max_scale_x") > c.at("min_scale_x"))
        moved += code(resorted.log_scales[3 * k], c.at("min_scale_x"), c.at("max_scale_x"), 11) !=
                 (source.packed[i][2] >> 21);
    }
    EXPECT_GT(moved, 0u) << "re-sorted, every x log-scale code came back: the order need not be kept";
    std::cout << path << ": re-sorted, " << moved << " of " << m.size() << " x log-scale codes not recovered\n";
  }
}

TEST(CompactScene, PictureOfARealCityKeepsWithinAFewLevels) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const test::SmallCity& c = test::small_flowers_city();
  auto quantized = std::make_shared<GaussianModel>(*c.lod);
  quantize_compact(*quantized);
  RenderOptions o;
  o.pipeline = Pipeline::exact;
  auto a = make_renderer("cpu", c.lod, o);
  auto b = make_renderer("cpu", quantized, o);
  Image ia, ib;
  for (std::size_t k = 0; k < c.views.size(); k += 4) {
    a->render(c.views[k], ia);
    b->render(c.views[k], ib);
    // 57 dB measured on the 13-copy city (RESULTS.md "Compact scene"); a field decoded with the
    // wrong range or bits falls far below.
    EXPECT_GE(psnr_rgba8(ia, ib), 45.0) << "view " << k;
  }
}

TEST(CompactScene, DamagedOrForgedFilesNameTheFileAndTheFault) {
  CATGS_REQUIRE_DATA(tumblewood, "scenes/tumblewood_sh2.ply");
  const std::string dir = test::temp_dir(), good = dir + "/good.catgs";
  const GaussianModel lod = build_lod(load_scene(tumblewood));
  write_compact_scene(lod, good);
  const std::string bytes = read_bytes(good);
  auto refused = [&](const std::string& name, const std::string& b, const std::string& says) {
    const std::string file = dir + "/" + name + ".catgs";
    write_bytes(file, b);
    test::expect_refused<SceneFileError>([&] { (void)load_scene(file); }, file, says);
  };
  refused("short", bytes.substr(0, 100), "shorter than its header");
  refused("cut", bytes.substr(0, bytes.size() - 39), "truncated");
  std::string flipped = bytes;
  flipped[flipped.size() - 5] ^= 1;
  refused("flipped", flipped, "checksum mismatch in data block");
  // Forged: the hashes recomputed (reseal_compact_scene), so the checks behind them decide.
  auto forged = [&](const std::string& name, uint64_t at, const void* value, std::size_t n, const std::string& says,
                    uint64_t at2 = 0, const void* value2 = nullptr) {
    std::string b = bytes;
    std::memcpy(&b[at], value, n);
    if (value2) std::memcpy(&b[at2], value2, n);
    reseal_compact_scene(b);
    refused(name, b, says);
  };
  const float nan = NAN, big = 3e38f, neg = -3e38f;
  forged("nan_range", 256, &nan, 4, "position range not finite");
  // Ordered and finite, but hi - lo overflows: a decode could reach infinity.
  forged("wide_range", 256, &neg, 4, "position range not finite or not ordered", 256 + 12, &big);
  forged("unordered", 256, &big, 4, "position range not finite or not ordered");
  const float negative_band = -1.0f;
  forged("band", 256 + 72, &negative_band, 4, "SH band bound");
  const uint64_t huge = uint64_t(1) << 40;
  forged("count", 16, &huge, 8, "larger than the file");
  const uint32_t version = 99;
  forged("version", 8, &version, 4, "version 99");
  // A LOD node whose parent is itself (the tables start at 256; the nodes follow the ranges).
  const uint64_t chunks = lod.lod.size(), node0 = 256 + chunks * 84;
  const uint32_t self = 0;
  forged("tree", node0 + 28, &self, 4, "LOD node 0");
  // A clean reseal changes nothing.
  std::string same = bytes;
  reseal_compact_scene(same);
  EXPECT_EQ(same, bytes);
}

TEST(CompactScene, KeyedLodFileFollowsItsSource) {
  CATGS_REQUIRE_DATA(path, "scenes/tumblewood_sh2.ply");
  const std::string dir = test::temp_dir(), scene = dir + "/tw.ply", out = dir + "/tw.ply.catgs-lod";
  fs::copy_file(path, scene);
  GaussianModel lod = build_lod(load_scene(scene));
  write_compact_scene(lod, out, scene);
  const GaussianModel read = load_lod_file(out, scene);  // either form of LOD file
  quantize_compact(lod);
  test::expect_same_gaussians(read, lod);
  EXPECT_EQ(read.name, "tw");
  auto rejected = [&](const std::string& file, const std::string& says) {
    test::expect_refused<SceneCacheRejected>([&] { (void)load_lod_file(file, scene); }, file, says);
  };
  const std::string alone = dir + "/alone.catgs";
  write_compact_scene(lod, alone);
  rejected(alone, "not keyed");
  // Merged levels of another merge rule (a build before rule 2 wrote 0 there): rebuilt. The rule
  // sits at byte 68 of the header, after the source stamp and the keyed flag.
  std::string bytes = read_bytes(out);
  uint32_t rule = 0;
  std::memcpy(&rule, bytes.data() + 68, 4);
  EXPECT_EQ(rule, fm::kLodMergeRule);
  const uint32_t old_rule = 0;
  std::memcpy(&bytes[68], &old_rule, 4);
  reseal_compact_scene(bytes);
  const std::string older = dir + "/tw_old_rule.ply.catgs-lod";
  write_bytes(older, bytes);
  rejected(older, "merge rule 0, this build's is " + std::to_string(fm::kLodMergeRule));
  fs::last_write_time(scene, fs::last_write_time(scene) + std::chrono::hours(1));
  rejected(out, "the source changed");
  // Full detail from a compact scene with levels: the leaves alone.
  const GaussianModel leaves = lod_leaves(read);
  EXPECT_TRUE(leaves.lod.empty());
  EXPECT_EQ(leaves.size(), lod_leaf_gaussians(read));
}

}  // namespace
}  // namespace catgs
