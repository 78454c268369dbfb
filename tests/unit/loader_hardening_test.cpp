// Issue 22, findings 1-4: crafted scene files that overflowed, read out of bounds, allocated
// without bound or converted out-of-range floats on the old loaders, and non-finite radii in the
// forward model's tile bounds. Each must now end in a clear SceneFileError (or a defined rectangle).
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "forward_model/forward_model.h"
#include "scene/ply_format.h"
#include "scene/ply_io.h"
#include "scene_files.h"
#include "test_data.h"

namespace catgs {
namespace {

using test::expect_scene_error;
using test::replace_in_header;

// The 14 INRIA properties every scene needs.
const char* const kInriaProperties[] = {"x",       "y",       "z",       "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                                        "scale_0", "scale_1", "scale_2", "rot_0",  "rot_1",  "rot_2",  "rot_3"};

// A PLY header (without the end_header line) of `format` with one INRIA vertex element of `count`
// rows, its 14 properties of `type` followed by `extra` property names.
std::string inria_header(const std::string& format, const std::string& count, const std::string& type = "float",
                         const std::vector<std::string>& extra = {}) {
  std::string h = "ply\nformat " + format + " 1.0\nelement vertex " + count + "\n";
  for (const char* p : kInriaProperties) h += "property " + type + " " + p + "\n";
  for (const auto& p : extra) h += "property " + type + " " + p + "\n";
  return h;
}

class LoaderHardeningTest : public ::testing::Test {
 protected:
  std::string save(const std::string& name, const std::string& bytes) {
    const std::string p = test::temp_dir() + "/" + name;
    test::write_bytes(p, bytes);
    return p;
  }
};

// Finding 1: 2^60 rows x 16 values wrap to 0 in 64 bits; the old reader sized its row buffer
// from the wrapped product and wrote the parsed values past it.
TEST_F(LoaderHardeningTest, AsciiRowCountTimesPropertiesMustNotWrap) {
  const std::string count = std::to_string(1ull << 60);
  const std::string text =
      inria_header("ascii", count, "float", {"nx", "ny"}) + "end_header\n0 0 0 0 0 0 0 0 0 0 1 0 0 0 0 0\n";
  expect_scene_error(save("wrap.ply", text), "element 'vertex' declares " + count + " rows of 16 values");
}

// Finding 2: without '\n' after end_header the old body offset was one past the file; a vertex
// row there and a padding element whose size wraps the offset back to the file size passed every
// size check, and the vertex was read from past the end of the buffer.
TEST_F(LoaderHardeningTest, BinaryHeaderWithoutNewlineAfterEndHeader) {
  const uint64_t wrap = std::numeric_limits<uint64_t>::max() - 56;  // 2^64 - 57: back to the file size
  const std::string text = inria_header("binary_little_endian", "1") + "element pad " + std::to_string(wrap) +
                           "\nproperty uchar p\nend_header";
  expect_scene_error(save("nonl.ply", text), "no newline after end_header");
}

// Finding 3: the same off-by-one made the ascii body size 2^64 - 1, so the size check passed and
// the row buffer was sized from the header's counts (2.19 GB for a 348-byte file).
TEST_F(LoaderHardeningTest, AsciiHeaderWithoutNewlineAfterEndHeader) {
  expect_scene_error(save("nonl_ascii.ply", inria_header("ascii", "1000") + "end_header"),
                     "no newline after end_header");
  expect_scene_error(save("nonl_crlf.ply", inria_header("ascii", "1000") + "end_header\r"),
                     "no newline after end_header");
}

// Finding 4: packed_* declared float loaded silently through an undefined float-to-uint32 cast.
TEST_F(LoaderHardeningTest, CompressedPackedPropertiesMustBeUint32) {
  const std::string biker = test::read_bytes(test::bundled_scene());
  ASSERT_FALSE(biker.empty());
  for (const char* name : {"packed_position", "packed_rotation", "packed_scale", "packed_color"}) {
    const std::string from = std::string("property uint ") + name;
    expect_scene_error(save("float_packed.ply", replace_in_header(biker, from, std::string("property float ") + name)),
                       std::string("property '") + name + "' of element 'vertex' must be uint32");
  }
}

// Finding 4: the compressed format's SH bytes are uint8; a signed char -1 would be cast to uint32.
TEST_F(LoaderHardeningTest, CompressedShPropertiesMustBeUint8) {
  GaussianModel m;
  m.sh_degree = 1;
  m.resize(3);
  for (std::size_t i = 0; i < m.size(); ++i) {
    m.means[3 * i] = static_cast<float>(i);
    m.rotations[4 * i] = 1.0f;
  }
  const std::string path = test::temp_dir() + "/sh.compressed.ply";
  write_compressed_ply(m, path);
  ASSERT_NO_THROW(load_scene(path));  // the writer's own types load
  const std::string bytes = test::read_bytes(path);
  expect_scene_error(save("char_sh.ply", replace_in_header(bytes, "property uchar f_rest_3", "property char f_rest_3")),
                     "property 'f_rest_3' of element 'sh' must be uint8");
}

// Finding 4: an ascii element of 2^64 - 1 rows without properties was accepted (and its rows
// walked one by one).
TEST_F(LoaderHardeningTest, AsciiElementWithoutPropertiesIsRefused) {
  const std::string text = "ply\nformat ascii 1.0\nelement junk 18446744073709551615\n" +
                           inria_header("ascii", "1").substr(std::string("ply\nformat ascii 1.0\n").size()) +
                           "end_header\n0 0 0 0 0 0 0 0 0 0 1 0 0 0\n";
  expect_scene_error(save("junk.ply", text), "element 'junk' has no properties");
}

// A double beyond float range made the old double-to-float conversion undefined.
TEST_F(LoaderHardeningTest, DoubleOutsideFloatRangeIsRefused) {
  const std::string text = inria_header("ascii", "1", "double") + "end_header\n0 1e300 0 0 0 0 0 0 0 0 1 0 0 0\n";
  expect_scene_error(save("big.ply", text), "value outside float range in element 'vertex' row 0 property 'y'");
}

// Found after the issue: in an ascii file every value is parsed as a double whatever its declared
// type, so a uint packed_* or uchar SH code of 5e9, -1, 1.5 or nan reached the compressed loader's
// double-to-uint32 conversion (undefined). A value must fit its declared type, as in a binary file.
TEST_F(LoaderHardeningTest, AsciiValueMustFitItsDeclaredType) {
  auto file = [&](const std::string& type, const std::string& value) {
    std::string h = inria_header("ascii", "1");
    h += "property " + type + " extra\nend_header\n0 0 0 0 0 0 0 0 0 0 1 0 0 0 " + value + "\n";
    return save("ascii_" + type + ".ply", h);
  };
  for (const char* bad : {"5000000000", "-1", "1.5", "nan", "inf"}) {
    SCOPED_TRACE(bad);
    expect_scene_error(file("uint", bad), "row 0 property 'extra' does not fit its type");
  }
  expect_scene_error(file("uchar", "256"), "ascii value 256 at element 'vertex' row 0 property 'extra'");
  expect_scene_error(file("float", "1e39"), "does not fit its type");
  // The ends of each range, and float's own inf and nan (the loaders judge those), still read.
  for (const auto& [type, value] : std::vector<std::pair<std::string, std::string>>{{"uint", "4294967295"},
                                                                                    {"uint", "0"},
                                                                                    {"uchar", "255"},
                                                                                    {"char", "-128"},
                                                                                    {"float", "inf"},
                                                                                    {"float", "nan"}}) {
    SCOPED_TRACE(type + " " + value);
    EXPECT_NO_THROW(ply::read_file(file(type, value)));
  }
}

// Finding 4: an infinite radius made static_cast<int> undefined in the vanilla tile bounds (on
// x86 it gave INT_MIN, so a Gaussian covering the screen listed no tile).
TEST(ForwardModelGuards, SquareTileRectWithNonFiniteRadius) {
  // volatile: the compiler must not fold the conversion (the old code's result then depended on
  // the optimiser; at run time x86 gave INT_MIN).
  volatile float inf_at_run_time = std::numeric_limits<float>::infinity();
  const float inf = inf_at_run_time, nan = std::numeric_limits<float>::quiet_NaN();
  const fm::TileRect all = fm::square_tile_rect({100.0f, 50.0f}, inf, 80, 45);
  EXPECT_EQ(all.x0, 0);
  EXPECT_EQ(all.y0, 0);
  EXPECT_EQ(all.x1, 80);
  EXPECT_EQ(all.y1, 45);
  EXPECT_EQ(fm::tile_count(fm::square_tile_rect({100.0f, 50.0f}, nan, 80, 45)), 0);
  EXPECT_EQ(fm::tile_count(fm::square_tile_rect({nan, 50.0f}, 3.0f, 80, 45)), 0);
  // Means far outside int range on either side: empty, not wrapped into the grid.
  EXPECT_EQ(fm::tile_count(fm::square_tile_rect({1e30f, 50.0f}, 3.0f, 80, 45)), 0);
  EXPECT_EQ(fm::tile_count(fm::square_tile_rect({-1e30f, 50.0f}, 3.0f, 80, 45)), 0);
  // Finite values keep the reference's truncation: a radius-3 square at (100, 50).
  const fm::TileRect r = fm::square_tile_rect({100.0f, 50.0f}, 3.0f, 80, 45);
  EXPECT_EQ(r.x0, 6);
  EXPECT_EQ(r.x1, 7);
  EXPECT_EQ(r.y0, 2);
  EXPECT_EQ(r.y1, 4);
}

// A 2D covariance that overflowed float has no conic (its NaN conic would reach the blend).
TEST(ForwardModelGuards, ConicOfNonFiniteCovarianceIsRefused) {
  const float inf = std::numeric_limits<float>::infinity();
  glm::vec3 conic;
  EXPECT_FALSE(fm::conic_from_cov2d({inf, 0.0f, 1.0f}, &conic));
  EXPECT_FALSE(fm::conic_from_cov2d({inf, inf, inf}, &conic));
  EXPECT_TRUE(fm::conic_from_cov2d({2.0f, 0.5f, 1.0f}, &conic));
  EXPECT_FLOAT_EQ(conic.x, 1.0f / 1.75f);
}

}  // namespace
}  // namespace catgs
