// SOG (sog_file.h) against PlayCanvas's splat-transform 2.7.1, which writes it (on the CPU, -g cpu)
// and decodes it: our read of its file must render as its decode of the same file does (>= 50 dB,
// CPU renderer, the views of scene_reference_test.cpp), bundled (.sog) and unbundled (meta.json);
// version 1, which it reads but no longer writes, is made here and compared value by value with its
// decode; damaged copies of its files fail naming the file and the problem.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <map>
#include <random>
#include <regex>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>

#include "scene/ply_io.h"
#include "scene/scene_peek.h"
#include "scene/sog_file.h"
#include "splat_transform.h"
#include "test_data.h"

#ifdef CATGS_TEST_WEBP_ENCODER
#include <webp/encode.h>
#endif

namespace catgs {
namespace {

namespace fs = std::filesystem;

constexpr double kSameDecodeDb = 50.0;
// k-means over the SH rest coefficients makes writing SOG slow on the CPU (minutes for the 38 K
// Gaussians of flowers_sh3): one iteration, and flowers decimated by splat-transform to a few
// thousand Gaussians, which still gives a palette of 2048 entries and all three SH bands.
constexpr const char* kWriteOnCpu = "-g cpu -i 1";
constexpr const char* kDecimateFlowers = "-F 4000";

#define CATGS_REQUIRE_SOG() \
  if (!sog_supported())     \
  GTEST_SKIP() << "this build has no SOG support (libwebp-dev and libzip-dev missing at configure time)"

struct Written {
  std::string path, error;
};

// splat-transform's SOG of the bundled biker ("biker.sog") or of decimated flowers_sh3
// ("flowers.sog", "flowers/meta.json"), written once per test process (writing is the slow part)
// into a folder of the process's own (ctest runs each test in a process, maybe several at once).
const Written& written(const std::string& name) {
  static struct Cache {
    fs::path dir = fs::temp_directory_path() / "catgs_tests" / ("sog_written." + std::to_string(::getpid()));
    std::map<std::string, Written> files;
    ~Cache() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } cache;
  if (const auto it = cache.files.find(name); it != cache.files.end()) return it->second;
  Written w{(cache.dir / name).string(), ""};
  fs::create_directories(fs::path(w.path).parent_path());
  const bool flowers = name.rfind("flowers", 0) == 0;
  const std::string source = flowers ? test::data_file("scenes/flowers_sh3.ply") : test::bundled_scene();
  const auto t0 = std::chrono::steady_clock::now();
  w.error = test::splat_transform(source, w.path, kWriteOnCpu, flowers ? kDecimateFlowers : "");
  const std::chrono::duration<double> took = std::chrono::steady_clock::now() - t0;
  std::cout << "[ info ] splat-transform wrote " << name << " in " << took.count() << " s\n";
  return cache.files[name] = w;
}

#define REQUIRE_WRITTEN(var, name)    \
  const Written& var = written(name); \
  ASSERT_TRUE(var.error.empty()) << var.error

TEST(SogReference, BikerWrittenBySplatTransform) {
  CATGS_REQUIRE_SOG();
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  REQUIRE_WRITTEN(sog, "biker.sog");
  const double psnr = test::psnr_against_reference_decode(sog.path, test::temp_dir());
  std::cout << "[ info ] biker -> splat-transform .sog: ours vs its decode " << psnr << " dB\n";
  EXPECT_GE(psnr, kSameDecodeDb);
  EXPECT_EQ(load_scene(sog.path).name, "biker");
}

// Degree 3 (shN's palette, labels and codebook, and the order of the SH coefficients), bundled
// (.sog) and unbundled (meta.json with the images beside it; the scene is named by its folder).
class SogFlowersTest : public ::testing::TestWithParam<const char*> {};

TEST_P(SogFlowersTest, WrittenBySplatTransform) {
  CATGS_REQUIRE_SOG();
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  REQUIRE_WRITTEN(sog, GetParam());
  const GaussianModel ours = load_scene(sog.path);
  EXPECT_EQ(ours.name, "flowers");
  const ScenePeek peek = peek_scene(sog.path);
  EXPECT_EQ(peek.name, "flowers");
  EXPECT_EQ(peek.format, "sog");
  EXPECT_EQ(peek.gaussians, ours.size());
  EXPECT_EQ(peek.sh_degree, 3);
  const double psnr = test::psnr_against_reference_decode(sog.path, test::temp_dir(), cams);
  std::cout << "[ info ] flowers_sh3 (decimated) -> splat-transform " << GetParam() << ": ours vs its decode " << psnr
            << " dB\n";
  EXPECT_GE(psnr, kSameDecodeDb);
}

INSTANTIATE_TEST_SUITE_P(Layouts, SogFlowersTest, ::testing::Values("flowers.sog", "flowers/meta.json"),
                         [](const auto& p) { return std::string(p.index == 0 ? "Bundled" : "Unbundled"); });

// Listing reads meta.json only; the format comes from the content, not the name.
TEST(SogReference, PeekAndDetectionByContent) {
  CATGS_REQUIRE_SOG();
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  REQUIRE_WRITTEN(sog, "biker.sog");
  const GaussianModel biker = load_scene(sog.path);
  const ScenePeek peek = peek_scene(sog.path);
  EXPECT_EQ(peek.format, "sog");
  EXPECT_EQ(peek.gaussians, biker.size());
  EXPECT_EQ(peek.sh_degree, biker.sh_degree);
  const std::string misnamed = test::temp_dir() + "/really_sog.ply";
  fs::copy_file(sog.path, misnamed);
  const GaussianModel again = load_scene(misnamed);
  EXPECT_EQ(again.name, "really_sog");
  EXPECT_EQ(again.means, biker.means);
}

std::string contents(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// `text` with the first match of `re` replaced by `with` (a test failure when there is none).
std::string replaced(const std::string& text, const std::string& re, const std::string& with) {
  std::smatch m;
  EXPECT_TRUE(std::regex_search(text, m, std::regex(re))) << re;
  return std::regex_replace(text, std::regex(re), with, std::regex_constants::format_first_only);
}

// Loading `path` fails with a SceneFileError naming it and saying `what`.
void expect_error(const std::string& path, const std::string& what) {
  try {
    load_scene(path);
    ADD_FAILURE() << path << " loaded";
  } catch (const SceneFileError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << "wanted '" << what << "': " << e.what();
  }
}

TEST(SogReference, DamagedArchiveNamesTheProblem) {
  CATGS_REQUIRE_SOG();
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  REQUIRE_WRITTEN(sog, "biker.sog");
  const std::string bytes = contents(sog.path), dir = test::temp_dir();
  auto write = [&](const std::string& name, const std::string& content) {
    std::ofstream(dir + "/" + name, std::ios::binary) << content;
    return dir + "/" + name;
  };
  expect_error(write("truncated.sog", bytes.substr(0, bytes.size() / 2)), "not a readable zip archive");
  // The entry's name in its local header and in the central directory (same length: offsets hold).
  std::string renamed = bytes;
  for (std::size_t at; (at = renamed.find("meta.json")) != std::string::npos;) renamed.replace(at, 9, "meta.jsoX");
  expect_error(write("no_meta.sog", renamed), "the archive has no entry 'meta.json'");
  // A byte of the first entry's data changed: its CRC no longer matches.
  std::string flipped = bytes;
  flipped[bytes.size() / 8] = static_cast<char>(~flipped[bytes.size() / 8]);
  expect_error(write("flipped.sog", flipped), "corrupt archive entry 'means_l.webp'");
}

// A copy of splat-transform's unbundled flowers with meta.json's text changed by `edit`.
template <typename Edit>
std::string edited_copy(const std::string& name, Edit edit) {
  const fs::path from = fs::path(written("flowers/meta.json").path).parent_path();
  const fs::path to = fs::path(test::temp_dir()) / name;
  fs::copy(from, to, fs::copy_options::recursive);
  const std::string meta = (to / "meta.json").string();
  const std::string text = edit(contents(meta));
  std::ofstream(meta, std::ios::binary | std::ios::trunc) << text;
  return meta;
}

TEST(SogReference, DamagedUnbundledSceneNamesTheProblem) {
  CATGS_REQUIRE_SOG();
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  REQUIRE_WRITTEN(meta, "flowers/meta.json");
  const auto same = [](const std::string& s) { return s; };
  const std::string missing = edited_copy("missing_image", same);
  fs::remove(fs::path(missing).parent_path() / "quats.webp");
  expect_error(missing, "cannot open image 'quats.webp'");
  const std::string truncated = edited_copy("truncated_image", same);
  const std::string sh0 = (fs::path(truncated).parent_path() / "sh0.webp").string();
  const std::string sh0_bytes = contents(sh0);
  std::ofstream(sh0, std::ios::binary | std::ios::trunc) << sh0_bytes.substr(0, sh0_bytes.size() / 2);
  expect_error(truncated, "image 'sh0.webp' is corrupt WebP");
  // The top-level count comes before shN's.
  expect_error(
      edited_copy("big_count", [](const std::string& s) { return replaced(s, R"("count":\d+)", R"("count":9000)"); }),
      "too small for 9000 Gaussians");
  expect_error(
      edited_copy("version_3", [](const std::string& s) { return replaced(s, R"("version":2)", R"("version":3)"); }),
      "unsupported SOG version 3 (1 and 2 are read)");
  expect_error(
      edited_copy("no_codebook", [](const std::string& s) { return replaced(s, "\"codebook\"", "\"codebooX\""); }),
      "meta.json lacks 'scales.codebook'");
  expect_error(edited_copy("string_count",
                           [](const std::string& s) { return replaced(s, R"("count":(\d+))", R"("count":"$1")"); }),
               "meta.json 'count' must be a whole number");
  expect_error(edited_copy("not_json", [](const std::string& s) { return s.substr(0, s.size() / 2); }),
               "meta.json is not a JSON object");
  expect_error(
      edited_copy("small_palette",
                  [](const std::string& s) { return replaced(s, R"("count":\d+,"bands")", R"("count":1,"bands")"); }),
      "past the 1-entry palette");
  expect_error(
      edited_copy("escape", [](const std::string& s) { return replaced(s, R"("quats.webp")", R"("../quats.webp")"); }),
      "image name '../quats.webp' leaves meta.json's folder");
}

#ifdef CATGS_TEST_WEBP_ENCODER

void write_lossless_webp(const std::string& path, const std::vector<uint8_t>& rgba, int width, int height) {
  uint8_t* out = nullptr;
  const std::size_t size = WebPEncodeLosslessRGBA(rgba.data(), width, height, width * 4, &out);
  ASSERT_GT(size, 0u) << path;
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(out), static_cast<std::streamsize>(size));
  WebPFree(out);
}

// Version 1 (linear ranges instead of codebooks, no "version" key), which splat-transform 2.7.1
// reads but no longer writes: a scene of random texels made here, read by us and decoded by
// splat-transform; every value must agree (the decode is exact up to float rounding, so the
// comparison is of numbers, not renders).
TEST(SogReference, Version1DecodedAsSplatTransformDoes) {
  CATGS_REQUIRE_SOG();
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  constexpr int kCount = 300, kWidth = 20, kHeight = 16, kPalette = 128;  // 1 SH band: 192 x 2 centroids
  const std::string dir = test::temp_dir();
  std::mt19937 rng(18);
  auto image = [&](const std::string& name, int width, int height, auto alpha) {
    std::vector<uint8_t> rgba(static_cast<std::size_t>(width * height) * 4);
    for (std::size_t i = 0; i < rgba.size(); ++i) rgba[i] = static_cast<uint8_t>(i % 4 == 3 ? alpha() : rng() % 256);
    write_lossless_webp(dir + "/" + name, rgba, width, height);
  };
  auto opaque = [] { return 255; };
  for (const char* name : {"means_l.webp", "means_u.webp", "scales.webp"}) image(name, kWidth, kHeight, opaque);
  image("quats.webp", kWidth, kHeight, [&] { return 252 + static_cast<int>(rng() % 4); });
  image("sh0.webp", kWidth, kHeight, [&] { return static_cast<int>(rng() % 256); });
  image("shN_centroids.webp", 64 * 3, kPalette / 64, opaque);
  std::vector<uint8_t> labels(static_cast<std::size_t>(kWidth * kHeight) * 4, 255);
  for (std::size_t i = 0; i < labels.size(); i += 4)
    labels[i] = static_cast<uint8_t>(rng() % kPalette), labels[i + 1] = 0;
  write_lossless_webp(dir + "/shN_labels.webp", labels, kWidth, kHeight);
  const std::string n = std::to_string(kCount);
  std::ofstream(dir + "/meta.json") << R"({"means":{"shape":[)" << n
                                    << R"(,3],"dtype":"float32","mins":[-2,-1,-3],"maxs":[2,1.5,3],)"
                                    << R"("files":["means_l.webp","means_u.webp"]},)"
                                    << R"("scales":{"shape":[)" << n
                                    << R"(,3],"dtype":"float32","mins":[-6,-7,-5],"maxs":[-1,-2,0],)"
                                    << R"("files":["scales.webp"]},)"
                                    << R"("quats":{"shape":[)" << n
                                    << R"(,4],"dtype":"uint8","encoding":"quaternion_packed","files":["quats.webp"]},)"
                                    << R"("sh0":{"shape":[)" << n
                                    << R"(,1,4],"dtype":"float32","mins":[-1,-2,-1.5,-4],"maxs":[2,1,1.5,6],)"
                                    << R"("files":["sh0.webp"]},)"
                                    << R"("shN":{"shape":[)" << n
                                    << R"(,9],"dtype":"float32","mins":-0.7,"maxs":0.6,"quantization":8,)"
                                    << R"("files":["shN_centroids.webp","shN_labels.webp"]}})";
  const std::string meta = dir + "/meta.json", decoded = dir + "/decoded.ply";
  const std::string err = test::splat_transform(meta, decoded);
  ASSERT_TRUE(err.empty()) << err;
  const GaussianModel ours = load_scene(meta), theirs = load_scene(decoded);
  ASSERT_EQ(ours.size(), static_cast<std::size_t>(kCount));
  ASSERT_EQ(theirs.size(), ours.size());
  EXPECT_EQ(ours.sh_degree, 1);
  EXPECT_EQ(theirs.sh_degree, 1);
  EXPECT_EQ(peek_scene(meta).gaussians, static_cast<std::uint64_t>(kCount));
  auto expect_near = [](const ModelArray& a, const ModelArray& b, const char* what) {
    ASSERT_EQ(a.size(), b.size()) << what;
    for (std::size_t i = 0; i < a.size(); ++i)
      ASSERT_NEAR(a[i], b[i], 1e-5 * std::max(1.0f, std::fabs(b[i]))) << what << "[" << i << "]";
  };
  expect_near(ours.means, theirs.means, "means");
  expect_near(ours.log_scales, theirs.log_scales, "log_scales");
  expect_near(ours.rotations, theirs.rotations, "rotations");
  expect_near(ours.opacity_logits, theirs.opacity_logits, "opacity_logits");
  expect_near(ours.sh, theirs.sh, "sh");
}

#endif  // CATGS_TEST_WEBP_ENCODER

}  // namespace
}  // namespace catgs
