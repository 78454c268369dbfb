// PlayCanvas's splat-transform 2.7.1 (npm, pinned in tests/e2e/package.json, installed by
// scripts/setup_web.sh) as the independent reference for the scene formats: it converts real scenes
// into each format and decodes any of them back to INRIA PLY, and the tests compare CPU renders of
// our reader's model with renders of its decode.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "camera/camera.h"
#include "scene/gaussian_model.h"

namespace catgs::test {

// Why splat-transform cannot run here (node or the npm package missing), or "" when it can.
std::string splat_transform_missing();

// Runs `splat-transform -q -w [extra] in [actions] out` (the output format follows out's extension;
// `actions` apply to the input, e.g. "-F 4000" to decimate). Returns "" on success, else the
// command and its exit status.
std::string splat_transform(const std::string& in, const std::string& out, const std::string& extra = "",
                            const std::string& actions = "");

// Cameras to compare renders at: training cameras 0, 60 and 120 of flowers_sh3 at 320x212 when
// `scene` is flowers (cameras file given), else an orbit of 3 views around the scene's robust bounds.
std::vector<Camera> comparison_views(const GaussianModel& scene, const std::string& cameras_json = "");

// The lowest PSNR (dB) over `views` of CPU renders of a against b.
double min_render_psnr(const GaussianModel& a, const GaussianModel& b, const std::vector<Camera>& views);

// Our reader (load_scene) on `file` against our INRIA reader on splat-transform's decode of it
// (written to dir/reference_decode.ply): the lowest render PSNR over comparison_views(reference,
// cameras_json). Counts and SH degrees must agree (a test failure, and 0 dB, otherwise).
double psnr_against_reference_decode(const std::string& file, const std::string& dir,
                                     const std::string& cameras_json = "");

}  // namespace catgs::test

// Skips the test with a visible reason when splat-transform cannot run.
#define CATGS_REQUIRE_SPLAT_TRANSFORM() \
  if (const std::string why = ::catgs::test::splat_transform_missing(); !why.empty()) GTEST_SKIP() << why
