// .spz and .splat readers on damaged files: a clear error naming the file and the problem, never a
// crash or an allocation the header alone asks for. (Their decoding is checked against
// splat-transform in scene_reference_test.cpp.)
#include <cmath>
#include <cstring>
#include <limits>

#include <gtest/gtest.h>

#include "scene/ply_io.h"
#include "scene/spz_file.h"
#include "scene_files.h"
#include "splat_transform.h"
#include "test_data.h"

namespace catgs {
namespace {

using test::expect_scene_error;
using test::read_bytes;

// Writes `bytes` to `path` and returns the path (scene_files.h).
std::string save(const std::string& path, const std::string& bytes) {
  test::write_bytes(path, bytes);
  return path;
}

class DamagedSpzTest : public ::testing::TestWithParam<int> {
 protected:
  void SetUp() override {
    dir_ = test::temp_dir();
    write_spz(*test::cached_scene(test::bundled_scene()), dir_ + "/biker.spz", GetParam());
    good_ = read_bytes(dir_ + "/biker.spz");
  }
  std::string dir_, good_;
};

TEST_P(DamagedSpzTest, TruncatedFails) {
  expect_scene_error(save(dir_ + "/cut.spz", good_.substr(0, good_.size() / 2)),
                     GetParam() == 4 ? "truncated" : "corrupt or truncated gzip");
}

TEST_P(DamagedSpzTest, GarbledStreamFails) {
  std::string b = good_;
  for (std::size_t i = b.size() / 2; i < b.size() / 2 + 64; ++i) b[i] = static_cast<char>(b[i] ^ 0x5a);
  expect_scene_error(save(dir_ + "/garbled.spz", b), GetParam() == 4 ? "corrupt zstd" : "gzip");
}

INSTANTIATE_TEST_SUITE_P(Versions, DamagedSpzTest, ::testing::Values(4, 3),
                         [](const auto& p) { return "v" + std::to_string(p.param); });

TEST(DamagedSpz, HugeDeclaredCountDoesNotAllocate) {
  const std::string dir = test::temp_dir();
  write_spz(*test::cached_scene(test::bundled_scene()), dir + "/biker.spz", 4);
  std::string b = read_bytes(dir + "/biker.spz");
  const uint32_t huge = 0xfffffff0u;
  std::memcpy(&b[8], &huge, 4);
  expect_scene_error(save(dir + "/huge.spz", b), "x the file size once decompressed");
}

TEST(DamagedSpz, UnsupportedVersionAndDegree) {
  const std::string dir = test::temp_dir();
  write_spz(*test::cached_scene(test::bundled_scene()), dir + "/biker.spz", 4);
  std::string b = read_bytes(dir + "/biker.spz");
  b[4] = 9;
  expect_scene_error(save(dir + "/v9.spz", b), "unsupported .spz version 9");
  b[4] = 4;
  b[12] = 4;
  expect_scene_error(save(dir + "/deg4.spz", b), "SH degree 4 is not supported");
}

std::string splat_record(float x) {
  std::string r(32, '\0');
  const float v[6] = {x, 0, 0, 0.1f, 0.1f, 0.1f};
  std::memcpy(&r[0], v, sizeof v);
  r[27] = static_cast<char>(200);
  r[28] = static_cast<char>(255);  // w = 1
  for (int k = 29; k < 32; ++k) r[static_cast<std::size_t>(k)] = static_cast<char>(128);
  return r;
}

TEST(DamagedSplat, WholeRecordsOnlyAndNaNNamed) {
  const std::string dir = test::temp_dir();
  const GaussianModel ok = load_scene(save(dir + "/two.splat", splat_record(1) + splat_record(2)));
  EXPECT_EQ(ok.size(), 2u);
  EXPECT_FLOAT_EQ(ok.means[3], 2.0f);
  EXPECT_NEAR(ok.log_scales[0], std::log(0.1f), 1e-6);
  expect_scene_error(save(dir + "/odd.splat", splat_record(1) + "x"), "not a multiple of 32-byte records");
  expect_scene_error(save(dir + "/empty.splat", ""), "empty .splat file");
  expect_scene_error(save(dir + "/nan.splat", splat_record(1) + splat_record(std::numeric_limits<float>::quiet_NaN())),
                     "non-finite position x in record 1");
}

// Alpha bytes 0 and 255 (opacity exactly 0 and 1, whose logits are -+inf) load as the finite
// logits -+kOpacityLogitLimit, and a middle byte as a logit near 0.
void expect_alpha_ends(const GaussianModel& m, float middle_tolerance, const std::string& what) {
  ASSERT_EQ(m.size(), 3u) << what;
  for (float logit : m.opacity_logits) EXPECT_TRUE(std::isfinite(logit)) << what;
  EXPECT_EQ(m.opacity_logits[0], -kOpacityLogitLimit) << what;
  EXPECT_EQ(m.opacity_logits[1], kOpacityLogitLimit) << what;
  EXPECT_NEAR(m.opacity_logits[2], 0.0f, middle_tolerance) << what;
}

// .splat: records written here byte by byte (alpha is byte 27), alpha 0, 255 and 128 (logit
// ln(128 / 127)).
TEST(AlphaEnds, SplatBytesLoadAsClampedFiniteLogits) {
  std::string bytes;
  for (const int alpha : {0, 255, 128}) {
    std::string r = splat_record(1);
    r[27] = static_cast<char>(alpha);
    bytes += r;
  }
  expect_alpha_ends(load_scene(save(test::temp_dir() + "/alpha.splat", bytes)), 0.01f, ".splat");
}

// .spz and compressed PLY written by splat-transform (not by our writers) from an INRIA PLY of
// opacity logits -inf, +inf and 0: its quantiser stores alpha 0 and 255 for the infinite ones.
TEST(AlphaEnds, SplatTransformFilesLoadAsClampedFiniteLogits) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  const std::string dir = test::temp_dir();
  GaussianModel three;
  three.sh_degree = 0;
  three.resize(3);
  const float inf = std::numeric_limits<float>::infinity();
  const float logits[3] = {-inf, inf, 0.0f};
  for (std::size_t i = 0; i < 3; ++i) {
    three.means[3 * i] = static_cast<float>(i);
    for (int a = 0; a < 3; ++a) three.log_scales[3 * i + a] = -2.0f;
    three.rotations[4 * i] = 1.0f;
    three.opacity_logits[i] = logits[i];
  }
  write_inria_ply(three, dir + "/alpha.ply");
  for (const char* out : {"alpha.spz", "alpha.compressed.ply"}) {
    ASSERT_EQ(test::splat_transform(dir + "/alpha.ply", dir + "/" + out), "") << out;
    expect_alpha_ends(load_scene(dir + "/" + out), 0.02f, out);
  }
}

}  // namespace
}  // namespace catgs
