// Scene formats against an independent implementation, PlayCanvas's splat-transform 2.7.1: our
// reader on a file must render as splat-transform's decode of the same file does (>= 50 dB, CPU
// renderer, same pose), and splat-transform must read what our writers write. A round trip through
// our own reader and writer would pass with a wrong layout on both sides, so none is used here.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "scene/format_detect.h"
#include "scene/ply_io.h"
#include "scene/spz_file.h"
#include "splat_transform.h"
#include "test_data.h"

namespace catgs {
namespace {

constexpr double kSameDecodeDb = 50.0;

// Converts `in` with splat-transform to `out`, failing the test with the command on error.
#define CONVERT(in, out)                                        \
  do {                                                          \
    const std::string err = test::splat_transform((in), (out)); \
    ASSERT_TRUE(err.empty()) << err;                            \
  } while (0)

struct OurWriterCheck {
  double same = 0;   // splat-transform's decode of our file vs our reader on it
  double lossy = 0;  // splat-transform's decode of our file vs the original
};

// Writes flowers_sh3 with `write` to `ours`, has splat-transform decode it, and compares renders.
template <typename Write>
OurWriterCheck check_our_writer(const std::string& flowers, const std::string& cams, const std::string& ours,
                                Write write) {
  const GaussianModel original = load_scene(flowers);
  write(original, ours);
  const std::string decoded = ours + ".decoded.ply";
  const std::string err = test::splat_transform(ours, decoded);
  EXPECT_TRUE(err.empty()) << err;
  if (!err.empty()) return {};
  const GaussianModel reference = load_scene(decoded);
  EXPECT_EQ(reference.size(), original.size());
  EXPECT_EQ(reference.sh_degree, original.sh_degree);
  if (reference.size() != original.size()) return {};
  const auto views = test::comparison_views(original, cams);
  return {test::min_render_psnr(load_scene(ours), reference, views), test::min_render_psnr(original, reference, views)};
}

TEST(SplatTransformReference, CompressedPlyWrittenBySplatTransform) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const std::string dir = test::temp_dir(), file = dir + "/flowers.compressed.ply";
  CONVERT(flowers, file);
  const double psnr = test::psnr_against_reference_decode(file, dir, cams);
  std::cout << "[ info ] flowers_sh3 -> splat-transform compressed PLY: ours vs its decode " << psnr << " dB\n";
  EXPECT_GE(psnr, kSameDecodeDb);
}

// The bundled scene was written by SuperSplat 2.7.1: it must look as PlayCanvas's tools show it.
TEST(SplatTransformReference, BundledBikerWrittenBySuperSplat) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  const double psnr = test::psnr_against_reference_decode(test::bundled_scene(), test::temp_dir());
  std::cout << "[ info ] biker.compressed.ply (SuperSplat): ours vs splat-transform's decode " << psnr << " dB\n";
  EXPECT_GE(psnr, kSameDecodeDb);
}

// splat-transform reads our compressed PLY as our reader does, and the copy stays close to the
// original (lossy: 8-11 bit quantisation).
TEST(SplatTransformReference, ReadsOurCompressedPly) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const auto r = check_our_writer(flowers, cams, test::temp_dir() + "/ours.compressed.ply",
                                  [](const GaussianModel& m, const std::string& p) { write_compressed_ply(m, p); });
  std::cout << "[ info ] our compressed PLY of flowers_sh3: splat-transform's decode vs ours " << r.same
            << " dB, vs the original " << r.lossy << " dB\n";
  EXPECT_GE(r.same, kSameDecodeDb);
  EXPECT_GE(r.lossy, 30.0);
}

// A second real scene (tumblewood_sh2: SH degree 2, an outdoor capture, where flowers_sh3 is SH 3
// and biker SH 0): splat-transform's compressed PLY and .spz (v4 and v3) decode as its own decode
// does, and it reads our compressed PLY and .spz as ours does.
TEST(SplatTransformReference, TumblewoodBothWays) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(tumblewood, "scenes/tumblewood_sh2.ply");
  const std::string dir = test::temp_dir();
  for (const char* out : {"/t.compressed.ply", "/t4.spz", "/t3.spz"}) {
    SCOPED_TRACE(out);
    const std::string file = dir + out;
    const std::string err =
        test::splat_transform(tumblewood, file, std::string(out) == "/t3.spz" ? "--spz-version 3" : "");
    ASSERT_TRUE(err.empty()) << err;
    const double psnr = test::psnr_against_reference_decode(file, dir);
    std::cout << "[ info ] tumblewood_sh2 -> splat-transform " << out << ": ours vs its decode " << psnr << " dB\n";
    EXPECT_GE(psnr, kSameDecodeDb);
  }
  const auto ply = check_our_writer(tumblewood, "", dir + "/ours.compressed.ply",
                                    [](const GaussianModel& m, const std::string& p) { write_compressed_ply(m, p); });
  const auto spz = check_our_writer(tumblewood, "", dir + "/ours.spz",
                                    [](const GaussianModel& m, const std::string& p) { write_spz(m, p, 4); });
  std::cout << "[ info ] our compressed PLY / .spz of tumblewood_sh2: splat-transform's decode vs ours " << ply.same
            << " / " << spz.same << " dB\n";
  EXPECT_GE(ply.same, kSameDecodeDb);
  EXPECT_GE(spz.same, kSameDecodeDb);
}

// splat-transform reads our INRIA PLY writer's file as the scene we wrote (a lossless format: the
// renders agree to float rounding).
TEST(SplatTransformReference, ReadsOurInriaPly) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const auto r = check_our_writer(flowers, cams, test::temp_dir() + "/ours.ply",
                                  [](const GaussianModel& m, const std::string& p) { write_inria_ply(m, p); });
  std::cout << "[ info ] our INRIA PLY of flowers_sh3: splat-transform's decode vs ours " << r.same
            << " dB, vs the original " << r.lossy << " dB\n";
  EXPECT_GE(r.same, kSameDecodeDb);
  EXPECT_GE(r.lossy, kSameDecodeDb);
}

// .spz written by splat-transform, i.e. by Niantic's own writer (@adobe/spz, the WASM build of
// nianticlabs/spz): version 4 (zstd streams, its default) and version 3 (gzip).
class SpzVersionTest : public ::testing::TestWithParam<int> {};

TEST_P(SpzVersionTest, WrittenBySplatTransform) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const std::string dir = test::temp_dir(), file = dir + "/flowers.spz";
  const std::string err = test::splat_transform(flowers, file, "--spz-version " + std::to_string(GetParam()));
  ASSERT_TRUE(err.empty()) << err;
  const double psnr = test::psnr_against_reference_decode(file, dir, cams);
  std::cout << "[ info ] flowers_sh3 -> splat-transform .spz v" << GetParam() << ": ours vs its decode " << psnr
            << " dB\n";
  EXPECT_GE(psnr, kSameDecodeDb);
}

// Our .spz writer: splat-transform (Niantic's reader) decodes it as our reader does, and the copy
// stays close to the original.
TEST_P(SpzVersionTest, SplatTransformReadsOurs) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const auto r =
      check_our_writer(flowers, cams, test::temp_dir() + "/ours.spz",
                       [this](const GaussianModel& m, const std::string& p) { write_spz(m, p, GetParam()); });
  std::cout << "[ info ] our .spz v" << GetParam() << " of flowers_sh3: splat-transform's decode vs ours " << r.same
            << " dB, vs the original " << r.lossy << " dB\n";
  EXPECT_GE(r.same, kSameDecodeDb);
  EXPECT_GE(r.lossy, 30.0);
}

INSTANTIATE_TEST_SUITE_P(Versions, SpzVersionTest, ::testing::Values(4, 3),
                         [](const auto& p) { return "v" + std::to_string(p.param); });

// A .splat file as antimatter15's convert.py writes one (32-byte records; see splat_file.h).
void write_splat_like_convert_py(const GaussianModel& m, const std::string& path) {
  std::ofstream out(path, std::ios::binary);
  const std::size_t K = static_cast<std::size_t>(m.sh_coeffs());
  auto u8 = [](double v) { return static_cast<char>(static_cast<uint8_t>(std::clamp(v, 0.0, 255.0))); };
  for (std::size_t i = 0; i < m.size(); ++i) {
    char rec[32];
    for (int a = 0; a < 3; ++a) {
      const float p = m.means[3 * i + a], s = std::exp(m.log_scales[3 * i + a]);
      std::memcpy(rec + 4 * a, &p, 4);
      std::memcpy(rec + 12 + 4 * a, &s, 4);
      rec[24 + a] = u8((0.5 + 0.28209479177387814 * m.sh[i * K * 3 + a]) * 255.0);
    }
    rec[27] = u8(255.0 / (1.0 + std::exp(-m.opacity_logits[i])));
    double len = 0;
    for (int k = 0; k < 4; ++k) len += m.rotations[4 * i + k] * m.rotations[4 * i + k];
    for (int k = 0; k < 4; ++k) rec[28 + k] = u8(m.rotations[4 * i + k] / std::sqrt(len) * 128.0 + 128.0);
    out.write(rec, 32);
  }
}

TEST(SplatTransformReference, SplatRecordsDecodedAsSplatTransformDoes) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const std::string dir = test::temp_dir(), file = dir + "/flowers.splat";
  write_splat_like_convert_py(load_scene(flowers), file);
  const double psnr = test::psnr_against_reference_decode(file, dir, cams);
  std::cout << "[ info ] flowers_sh3 as .splat: ours vs splat-transform's decode " << psnr << " dB\n";
  EXPECT_GE(psnr, kSameDecodeDb);
}

// The format comes from the content: an .spz saved under a .ply name still loads as .spz.
TEST(SplatTransformReference, FormatDetectedByContent) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  const std::string dir = test::temp_dir(), spz = dir + "/flowers.spz", misnamed = dir + "/really_spz.ply";
  CONVERT(flowers, spz);
  std::filesystem::copy_file(spz, misnamed);
  const GaussianModel a = load_scene(spz), b = load_scene(misnamed);
  EXPECT_EQ(b.size(), a.size());
  EXPECT_EQ(b.means, a.means);
  EXPECT_EQ(b.name, "really_spz");
}

// .splat has no magic: its records are recognised (splat_file.h looks_like_splat), so a .splat
// saved under another name loads as the same scene, while other data named .bin stays "not a
// PLY file", and a .splat whose records fail the checks falls back to its extension only.
TEST(SceneFormatDetection, SplatRecognisedByItsRecords) {
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  const std::string dir = test::temp_dir(), splat = dir + "/flowers.splat", misnamed = dir + "/really_splat.bin";
  write_splat_like_convert_py(load_scene(flowers), splat);
  std::filesystem::copy_file(splat, misnamed);
  EXPECT_EQ(detect_scene_format(misnamed), SceneFormat::splat);
  std::vector<std::pair<uint64_t, uint64_t>> calls;
  const GaussianModel a = load_scene(splat, [&](uint64_t done, uint64_t total) { calls.emplace_back(done, total); });
  const GaussianModel b = load_scene(misnamed);
  ASSERT_GE(calls.size(), a.size() > 65536 ? 2u : 1u);  // a step every 65536 records, then the end
  for (std::size_t k = 1; k < calls.size(); ++k) EXPECT_GT(calls[k].first, calls[k - 1].first);
  EXPECT_EQ(calls.back(), std::make_pair(static_cast<uint64_t>(a.size()), static_cast<uint64_t>(a.size())));
  ASSERT_EQ(b.size(), a.size());
  EXPECT_EQ(b.means, a.means);
  EXPECT_EQ(b.rotations, a.rotations);

  // 4096 bytes that are not records (a 32-byte multiple, as .splat): text, then a record with a
  // zero quaternion (bytes 127.5 +- 0.5 decode to |q| ~ 0).
  const std::string text = dir + "/text.bin", flat = dir + "/flat.bin";
  {
    std::ofstream out(text, std::ios::binary);
    for (int i = 0; i < 128; ++i) out << "thirty-two bytes of plain text!\n";
  }
  {
    std::vector<char> bytes(std::filesystem::file_size(splat) < 4096 ? 0 : 4096);
    std::ifstream(splat, std::ios::binary).read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    for (int k = 0; k < 4; ++k) bytes[32 * 5 + 28 + k] = static_cast<char>(128);
    std::ofstream(flat, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }
  EXPECT_EQ(detect_scene_format(text), SceneFormat::ply);
  EXPECT_EQ(detect_scene_format(flat), SceneFormat::ply);
  try {
    load_scene(text);
    ADD_FAILURE() << "text loaded as a scene";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("text.bin"), std::string::npos) << e.what();
  }
  const std::string flat_splat = dir + "/flat.splat";
  std::filesystem::copy_file(flat, flat_splat);
  EXPECT_EQ(detect_scene_format(flat_splat), SceneFormat::splat);  // by its name, for its reader
}

// glTF 2.0 + KHR_gaussian_splatting written by splat-transform (its writeGlb). splat-transform 2.7.1
// cannot read .glb, so the reference is the scene it converted: the .glb holds float32 attributes
// (exp of log scale, sigmoid of logit, axes rotated 180 degrees about z), so our reader must render
// as the source does. A wrong axis, quaternion order, SH sign or activation fails this.
double psnr_glb_against_source(const std::string& source, const std::string& cams) {
  const std::string dir = test::temp_dir(), glb = dir + "/scene.glb";
  const std::string err = test::splat_transform(source, glb);
  EXPECT_TRUE(err.empty()) << err;
  if (!err.empty()) return 0.0;
  const GaussianModel ours = load_scene(glb);
  const GaussianModel reference = load_scene(source);
  EXPECT_EQ(ours.size(), reference.size());
  EXPECT_EQ(ours.sh_degree, reference.sh_degree);
  EXPECT_EQ(ours.name, "scene");
  if (ours.size() != reference.size()) return 0.0;
  return test::min_render_psnr(ours, reference, test::comparison_views(reference, cams));
}

TEST(SplatTransformReference, GlbWrittenBySplatTransform) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const double psnr = psnr_glb_against_source(flowers, cams);
  std::cout << "[ info ] flowers_sh3 -> splat-transform .glb: ours vs the source PLY " << psnr << " dB\n";
  EXPECT_GE(psnr, kSameDecodeDb);
}

TEST(SplatTransformReference, BundledBikerAsGlb) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  const double psnr = psnr_glb_against_source(test::bundled_scene(), "");
  std::cout << "[ info ] biker.compressed.ply -> splat-transform .glb: ours vs the source " << psnr << " dB\n";
  EXPECT_GE(psnr, kSameDecodeDb);
}

// Damaged .glb files from splat-transform: each fails naming the file and the problem.
TEST(SplatTransformReference, DamagedGlbNamesTheProblem) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  const std::string dir = test::temp_dir(), glb = dir + "/flowers.glb";
  CONVERT(flowers, glb);
  std::ifstream in(glb, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto expect_error = [&](const std::string& name, const std::string& content, const std::string& what) {
    const std::string path = dir + "/" + name;
    std::ofstream(path, std::ios::binary) << content;
    try {
      load_scene(path);
      ADD_FAILURE() << name << " loaded";
    } catch (const SceneFileError& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  auto replaced = [&](const std::string& from, const std::string& to) {
    std::string s = bytes;
    const std::size_t at = s.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) s.replace(at, from.size(), to);
    return s;
  };
  // Same lengths, so the GLB chunk sizes stay right and only the named thing is wrong.
  expect_error("no_ext.glb", replaced("\"KHR_gaussian_splatting\":{\"kernel", "\"KHR_gaussian_splattinX\":{\"kernel"),
               "no mesh primitive with the KHR_gaussian_splatting extension");
  expect_error("no_scale.glb", replaced("KHR_gaussian_splatting:SCALE", "KHR_gaussian_splatting:SCALX"),
               "missing attribute KHR_gaussian_splatting:SCALE");
  expect_error("truncated.glb", bytes.substr(0, bytes.size() / 2), "not valid glTF");
  // OPACITY pointed at COLOR_0's accessor (VEC4 unsigned byte), as splat-transform orders them:
  // a byte is a quantized type the reader takes (KHR_mesh_quantization), four of them are not.
  expect_error("byte_opacity.glb",
               replaced("\"KHR_gaussian_splatting:OPACITY\":4", "\"KHR_gaussian_splatting:OPACITY\":1"),
               "OPACITY has the wrong accessor type");
  // OPACITY's accessor (the only SCALAR) one element short.
  const std::size_t n = load_scene(flowers).size();
  const std::string count = "\"count\":" + std::to_string(n) + ",\"type\":\"SCALAR\"";
  const std::string fewer = "\"count\":" + std::to_string(n - 1) + ",\"type\":\"SCALAR\"";
  ASSERT_EQ(count.size(), fewer.size());
  expect_error("short_opacity.glb", replaced(count, fewer), "POSITION has " + std::to_string(n));
  // A count the buffer cannot hold is refused before anything is allocated for it.
  const std::string positions = "\"count\":" + std::to_string(n) + ",\"type\":\"VEC3\"";
  const std::string too_many = "\"count\":" + std::string(std::to_string(n).size(), '9') + ",\"type\":\"VEC3\"";
  expect_error("long_positions.glb", replaced(positions, too_many), "POSITION runs past the end of its buffer");
  // A NaN as the first Gaussian's x (POSITION is the BIN chunk's first accessor).
  uint32_t json_length = 0;
  std::memcpy(&json_length, bytes.data() + 12, 4);
  std::string nan = bytes;
  const uint32_t quiet_nan = 0x7fc00000u;
  std::memcpy(&nan[20 + json_length + 8], &quiet_nan, 4);
  expect_error("nan.glb", nan, "POSITION of Gaussian 0 is not finite");
  // A .gltf whose JSON lacks the extension: its name makes it glTF (format_detect.cpp: the
  // extension may be named past the first 4 KiB), and the reader says what it lacks.
  expect_error("plain.gltf", "{\"asset\":{\"version\":\"2.0\"}}",
               "no mesh primitive with the KHR_gaussian_splatting extension");
  // The same JSON under another name is not taken for glTF (detected by content).
  expect_error("plain.json", "{\"asset\":{\"version\":\"2.0\"}}", "not a PLY file");
}

}  // namespace
}  // namespace catgs
