// Scene formats against an independent implementation, PlayCanvas's splat-transform 2.7.1: our
// reader on a file must render as splat-transform's decode of the same file does (>= 50 dB, CPU
// renderer, same pose), and splat-transform must read what our writers write. A round trip through
// our own reader and writer would pass with a wrong layout on both sides, so none is used here.
#include <gtest/gtest.h>

#include "scene/ply_io.h"
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

// Our reader on `file` against our INRIA reader on splat-transform's decode of it.
double psnr_against_reference_decode(const std::string& file, const std::string& dir, const std::string& cameras = "") {
  const std::string decoded = dir + "/reference_decode.ply";
  const std::string err = test::splat_transform(file, decoded);
  EXPECT_TRUE(err.empty()) << err;
  if (!err.empty()) return 0.0;
  const GaussianModel ours = load_scene(file);
  const GaussianModel reference = load_scene(decoded);
  EXPECT_EQ(ours.size(), reference.size());
  EXPECT_EQ(ours.sh_degree, reference.sh_degree);
  if (ours.size() != reference.size()) return 0.0;
  return test::min_render_psnr(ours, reference, test::comparison_views(reference, cameras));
}

TEST(SplatTransformReference, CompressedPlyWrittenBySplatTransform) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const std::string dir = test::temp_dir(), file = dir + "/flowers.compressed.ply";
  CONVERT(flowers, file);
  const double psnr = psnr_against_reference_decode(file, dir, cams);
  std::cout << "[ info ] flowers_sh3 -> splat-transform compressed PLY: ours vs its decode " << psnr << " dB\n";
  EXPECT_GE(psnr, kSameDecodeDb);
}

// The bundled scene was written by SuperSplat 2.7.1: it must look as PlayCanvas's tools show it.
TEST(SplatTransformReference, BundledBikerWrittenBySuperSplat) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  const double psnr = psnr_against_reference_decode(test::bundled_scene(), test::temp_dir());
  std::cout << "[ info ] biker.compressed.ply (SuperSplat): ours vs splat-transform's decode " << psnr << " dB\n";
  EXPECT_GE(psnr, kSameDecodeDb);
}

// splat-transform reads our compressed PLY as our reader does, and the copy stays close to the
// original (lossy: 8-11 bit quantisation).
TEST(SplatTransformReference, ReadsOurCompressedPly) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const std::string dir = test::temp_dir(), ours = dir + "/ours.compressed.ply", decoded = dir + "/decoded.ply";
  const GaussianModel original = load_scene(flowers);
  write_compressed_ply(original, ours);
  CONVERT(ours, decoded);
  const GaussianModel reference = load_scene(decoded);
  const auto views = test::comparison_views(original, cams);
  const double same = test::min_render_psnr(load_scene(ours), reference, views);
  const double lossy = test::min_render_psnr(original, reference, views);
  std::cout << "[ info ] our compressed PLY of flowers_sh3: splat-transform's decode vs ours " << same
            << " dB, vs the original " << lossy << " dB\n";
  EXPECT_GE(same, kSameDecodeDb);
  EXPECT_GE(lossy, 30.0);
}

}  // namespace
}  // namespace catgs
