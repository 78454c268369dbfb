// Scene loaders and writers on the real scenes, and clear errors for corrupted copies of them.
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "common/image_io.h"
#include "scene/ply_io.h"
#include "renderer/renderer.h"
#include "camera/trace.h"
#include "scene_files.h"
#include "test_data.h"

namespace catgs {
namespace {

using test::expect_scene_error;
using test::read_bytes;
using test::replace_in_header;
using test::write_bytes;

struct SceneFacts {
  const char* file;
  std::size_t count;
  int sh_degree;
};

class RealSceneTest : public ::testing::TestWithParam<SceneFacts> {};

TEST_P(RealSceneTest, LoadsWithHeaderCountAndShDegree) {
  CATGS_REQUIRE_DATA(path, std::string("scenes/") + GetParam().file);
  const GaussianModel m = load_scene(path);
  EXPECT_EQ(m.size(), GetParam().count);
  EXPECT_EQ(m.sh_degree, GetParam().sh_degree);
  EXPECT_EQ(m.sh.size(), m.size() * 3 * static_cast<std::size_t>(sh_coeff_count(m.sh_degree)));
  EXPECT_NO_THROW(m.validate());
  for (std::size_t i = 0; i < m.size(); i += 97) {
    const float* q = &m.rotations[4 * i];
    EXPECT_GT(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1e-6f) << "Gaussian " << i;
  }
  const Bounds b = m.bounds();
  EXPECT_LT(b.min.x, b.max.x);
  EXPECT_LT(b.min.y, b.max.y);
}

INSTANTIATE_TEST_SUITE_P(Scenes, RealSceneTest,
                         ::testing::Values(SceneFacts{"biker.compressed.ply", 152746, 0},
                                           SceneFacts{"guitar.compressed.ply", 90854, 0},
                                           SceneFacts{"flowers_sh3.ply", 38347, 3},
                                           SceneFacts{"tumblewood_sh2.ply", 542104, 2}),
                         [](const auto& param_info) {
                           std::string n = param_info.param.file;
                           return n.substr(0, n.find('.'));
                         });

TEST(SceneLoader, BundledBikerLoadsWithoutSharedData) {
  const GaussianModel m = load_scene(test::bundled_scene());
  EXPECT_EQ(m.size(), 152746u);
  EXPECT_EQ(m.name, "biker");
  // Compressed opacity 255 must clamp, not give an infinite logit.
  for (float logit : m.opacity_logits) ASSERT_TRUE(std::isfinite(logit));
}

TEST(SceneLoader, FlowersFlatGaussiansAreAccepted) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const GaussianModel m = load_scene(path);
  std::size_t flat = 0;
  for (float s : m.log_scales) flat += s < -15.0f ? 1 : 0;
  EXPECT_EQ(flat, 10375u);  // data README: scale axes stored as log-scale about -26
}

TEST(SceneWriter, InriaRoundTripIsExact) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const GaussianModel a = load_scene(path);
  const std::string out = test::temp_dir() + "/flowers.ply";
  write_inria_ply(a, out);
  test::expect_same_gaussians(load_scene(out), a);
}

// ASCII PLY with the properties in a shuffled order and as doubles reads the same Gaussians.
TEST(SceneLoader, AsciiInAnyPropertyOrder) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const GaussianModel a = load_scene(path);
  const std::size_t n = 200;
  std::vector<std::string> props = {"x",       "y",       "z",       "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                                    "scale_0", "scale_1", "scale_2", "rot_0",  "rot_1",  "rot_2",  "rot_3"};
  for (int j = 0; j < 45; ++j) props.push_back("f_rest_" + std::to_string(j));
  std::shuffle(props.begin(), props.end(), std::mt19937(7));
  auto value = [&](std::size_t i, const std::string& p) -> double {
    if (p == "x" || p == "y" || p == "z") return a.means[3 * i + (p[0] - 'x')];
    if (p.rfind("f_dc_", 0) == 0) return a.sh[i * 48 + (p[5] - '0')];
    if (p == "opacity") return a.opacity_logits[i];
    if (p.rfind("scale_", 0) == 0) return a.log_scales[3 * i + (p[6] - '0')];
    if (p.rfind("rot_", 0) == 0) return a.rotations[4 * i + (p[4] - '0')];
    const int j = std::stoi(p.substr(7));  // f_rest_j, channel-major
    return a.sh[i * 48 + static_cast<std::size_t>(1 + j % 15) * 3 + static_cast<std::size_t>(j / 15)];
  };
  std::string text = "ply\nformat ascii 1.0\ncomment shuffled\nelement vertex " + std::to_string(n) + "\n";
  for (const auto& p : props) text += "property double " + p + "\n";
  text += "end_header\n";
  char buf[64];
  for (std::size_t i = 0; i < n; ++i) {
    for (const auto& p : props) {
      std::snprintf(buf, sizeof buf, "%.9g ", value(i, p));
      text += buf;
    }
    text += "\n";
  }
  const std::string out = test::temp_dir() + "/ascii.ply";
  write_bytes(out, text);
  const GaussianModel b = load_scene(out);
  ASSERT_EQ(b.size(), n);
  ASSERT_EQ(b.sh_degree, 3);
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) EXPECT_FLOAT_EQ(b.means[3 * i + k], a.means[3 * i + k]);
    for (int k = 0; k < 48; ++k) EXPECT_FLOAT_EQ(b.sh[i * 48 + k], a.sh[i * 48 + k]) << i << " " << k;
    EXPECT_FLOAT_EQ(b.opacity_logits[i], a.opacity_logits[i]);
  }
}

// The compressed writer keeps the SH degree and a render of the compact copy stays close.
TEST(SceneWriter, CompressedRoundTripRendersClose) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  auto a = std::make_shared<GaussianModel>(load_scene(path));
  const std::string out = test::temp_dir() + "/flowers.compressed.ply";
  write_compressed_ply(*a, out);
  auto b = std::make_shared<GaussianModel>(load_scene(out));
  ASSERT_EQ(b->size(), a->size());
  EXPECT_EQ(b->sh_degree, 3);
  const Bounds bounds = a->bounds();
  const glm::vec3 ext = bounds.extent();
  for (std::size_t i = 0; i < a->size(); i += 101)
    for (int k = 0; k < 3; ++k)  // quantized to 10-11 bits of a chunk range <= the scene extent
      EXPECT_NEAR(b->means[3 * i + k], a->means[3 * i + k], ext[k] / 1000.0f);
  const Camera cam = load_inria_cameras(cams, 320, 212).at(10);
  Image ia, ib;
  make_renderer("cpu", a, {})->render(cam, ia);
  make_renderer("cpu", b, {})->render(cam, ib);
  const double psnr = psnr_rgba8(ia, ib);
  std::cout << "[ info ] compressed copy of flowers_sh3: PSNR " << psnr << " dB vs original\n";
  EXPECT_GT(psnr, 25.0);
}

class CorruptSceneTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::temp_dir();
    biker_ = read_bytes(test::bundled_scene());
    flowers_path_ = test::data_file("scenes/flowers_sh3.ply");
    if (!flowers_path_.empty()) flowers_ = read_bytes(flowers_path_);
  }
  std::string save(const std::string& name, const std::string& bytes) {
    const std::string p = dir_ + "/" + name;
    write_bytes(p, bytes);
    return p;
  }
  bool have_flowers() const { return !flowers_.empty(); }
  std::string dir_, biker_, flowers_, flowers_path_;
};

TEST_F(CorruptSceneTest, MissingFile) { expect_scene_error(dir_ + "/nope.ply", "cannot open"); }

TEST_F(CorruptSceneTest, NotAPly) {
  expect_scene_error(save("json.ply", "[{\"id\": 0}]\n"), "not a PLY");
  expect_scene_error(save("empty.ply", ""), "not a PLY");
}

TEST_F(CorruptSceneTest, NoEndHeader) {
  expect_scene_error(save("noend.ply", biker_.substr(0, biker_.find("end_header"))), "no end_header");
}

TEST_F(CorruptSceneTest, TruncatedBody) {
  expect_scene_error(save("trunc.ply", biker_.substr(0, biker_.size() - 1000)), "truncated");
}

TEST_F(CorruptSceneTest, WrongCounts) {
  expect_scene_error(save("more.ply", replace_in_header(biker_, "element vertex 152746", "element vertex 152747")),
                     "truncated");
  expect_scene_error(save("less.ply", replace_in_header(biker_, "element vertex 152746", "element vertex 152745")),
                     "bytes after the last element");
  expect_scene_error(save("zero.ply", replace_in_header(biker_, "element chunk 597", "element chunk 0")),
                     "bytes after the last element");
}

TEST_F(CorruptSceneTest, AbsurdCountDoesNotAllocate) {
  // 2^31 rows of 16 bytes would be 32 GiB: the size check must refuse before allocating.
  expect_scene_error(save("huge.ply", replace_in_header(biker_, "element vertex 152746", "element vertex 2147483648")),
                     "truncated");
  expect_scene_error(save("neg.ply", replace_in_header(biker_, "element vertex 152746", "element vertex -5")),
                     "malformed element count");
}

TEST_F(CorruptSceneTest, MissingPackedProperty) {
  expect_scene_error(save("noscale.ply", replace_in_header(biker_, "packed_scale", "packed_scalx")),
                     "lacks property 'packed_scale'");
}

TEST_F(CorruptSceneTest, ChunkCountMismatch) {
  // Drop the last chunk row (18 floats) and declare 596 chunks: sizes agree, 256 per chunk does not.
  const std::size_t body = biker_.find("end_header\n") + 11;
  std::string b = replace_in_header(biker_.substr(0, body), "element chunk 597", "element chunk 596") +
                  biker_.substr(body, 596 * 72) + biker_.substr(body + 597 * 72);
  expect_scene_error(save("chunks.ply", b), "596 chunks cannot hold 152746 Gaussians");
}

TEST_F(CorruptSceneTest, UnsupportedFormat) {
  expect_scene_error(save("be.ply", replace_in_header(biker_, "binary_little_endian", "binary_big_endian")),
                     "unsupported PLY format");
}

TEST_F(CorruptSceneTest, InriaMissingProperty) {
  if (!have_flowers()) GTEST_SKIP() << "real data scenes/flowers_sh3.ply not found under CATGS_DATA_DIR";
  expect_scene_error(
      save("noopacity.ply", replace_in_header(flowers_, "property float opacity", "property float opacitz")),
      "lacks property 'opacity'");
}

TEST_F(CorruptSceneTest, InriaWrongShCount) {
  if (!have_flowers()) GTEST_SKIP() << "real data scenes/flowers_sh3.ply not found under CATGS_DATA_DIR";
  expect_scene_error(
      save("rest.ply", replace_in_header(flowers_, "property float f_rest_44", "property float g_rest_44")),
      "match no SH degree");
}

TEST_F(CorruptSceneTest, InriaNonFiniteValue) {
  if (!have_flowers()) GTEST_SKIP() << "real data scenes/flowers_sh3.ply not found under CATGS_DATA_DIR";
  for (const float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    std::string b = flowers_;
    const std::size_t body = b.find("end_header\n") + 11;
    std::memcpy(&b[body + 62 * 4 * 1000 + 4], &bad, 4);  // Gaussian 1000, property y
    expect_scene_error(save("nan.ply", b), "non-finite value in element 'vertex' row 1000 property 'y'");
  }
}

// Converters write alpha 0 / 1 as -inf / +inf logits: they clamp; NaN still fails, named.
TEST_F(CorruptSceneTest, InriaInfiniteOpacityClampsNaNFails) {
  if (!have_flowers()) GTEST_SKIP() << "real data scenes/flowers_sh3.ply not found under CATGS_DATA_DIR";
  const std::size_t body = flowers_.find("end_header\n") + 11, opacity = 4 * 54, row = 62 * 4;
  std::string b = flowers_;
  const float inf = std::numeric_limits<float>::infinity(), minus_inf = -inf;
  std::memcpy(&b[body + row * 1000 + opacity], &inf, 4);
  std::memcpy(&b[body + row * 1001 + opacity], &minus_inf, 4);
  const GaussianModel m = load_scene(save("inf.ply", b));
  EXPECT_EQ(m.opacity_logits[1000], kOpacityLogitLimit);
  EXPECT_EQ(m.opacity_logits[1001], -kOpacityLogitLimit);
  EXPECT_EQ(m.opacity_logits[1002], test::cached_scene(flowers_path_)->opacity_logits[1002]);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(&b[body + row * 1002 + opacity], &nan, 4);
  expect_scene_error(save("nan.ply", b), "non-finite value in element 'vertex' row 1002 property 'opacity'");
}

TEST_F(CorruptSceneTest, InriaTruncatedAscii) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float opacity\n"
      "property float scale_0\nproperty float scale_1\nproperty float scale_2\nproperty float rot_0\n"
      "property float rot_1\nproperty float rot_2\nproperty float rot_3\nend_header\n"
      "0 0 0 0 0 0 0 0 0 0 1 0 0 0\n1 1 1 0 0 0 0 0 0 0 1 0 0 0\n";
  expect_scene_error(save("short.ply", text), "truncated");
  expect_scene_error(save("words.ply", text + "0 0 0 zz 0 0 0 0 0 0 1 0 0 0\n"),
                     "malformed ascii value at element 'vertex' row 2 property 'f_dc_0'");
}

}  // namespace
}  // namespace catgs
