// Where tests find real data: CATGS_DATA_DIR (environment, else the build's default, normally
// ../shared/data beside the checkout) and the bundled assets.
#pragma once

#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "scene/gaussian_model.h"

namespace catgs::test {

// The real-data folder, or "" when it does not exist.
std::string data_dir();
// Path of a file under the data folder (scenes/..., traces/...), or "" when absent.
std::string data_file(const std::string& relative);
// The bundled biker scene (always present).
std::string bundled_scene();
// A fresh temporary folder for this test.
std::string temp_dir();
// The scene at `path`, loaded once per test process and shared (tests only read it).
std::shared_ptr<const GaussianModel> cached_scene(const std::string& path);

// Issue 22's hostile scene: n Gaussians of log-scale `log_scale` (5: each covers the whole view
// of a camera a few units away), opacity logit 5, identity rotation, means uniform in the unit
// box at the origin (seed 22).
std::shared_ptr<const GaussianModel> giant_gaussians(std::size_t n, float log_scale);

// Every per-Gaussian array of `got` (means, log-scales, rotations, opacity logits, SH) equals
// `want`'s bit for bit, and so does the SH degree.
inline void expect_same_gaussians(const GaussianModel& got, const GaussianModel& want) {
  EXPECT_EQ(got.sh_degree, want.sh_degree);
  EXPECT_EQ(got.means, want.means);
  EXPECT_EQ(got.log_scales, want.log_scales);
  EXPECT_EQ(got.rotations, want.rotations);
  EXPECT_EQ(got.opacity_logits, want.opacity_logits);
  EXPECT_EQ(got.sh, want.sh);
}

// `load()` must throw an E whose message names `file` and says `says` (a refused file names
// itself and its fault).
template <typename E, typename Load>
void expect_refused(Load&& load, const std::string& file, const std::string& says) {
  try {
    load();
    ADD_FAILURE() << file << ": accepted";
  } catch (const E& e) {
    EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << file << ": " << e.what();
  }
}

}  // namespace catgs::test

// Skips the test with a visible reason when a real-data file is missing.
#define CATGS_REQUIRE_DATA(var, relative)                                                                          \
  const std::string var = ::catgs::test::data_file(relative);                                                      \
  if (var.empty())                                                                                                 \
  GTEST_SKIP() << "real data '" << (relative) << "' not found under CATGS_DATA_DIR (" << ::catgs::test::data_dir() \
               << "); set CATGS_DATA_DIR to ../shared/data"
