// What the GPU tests (tests/gpu/*_test.cpp, GoogleTest, ctest label gpu) share: where the scenes
// and traces are, the scenes loaded once per process, the row table every check adds to (printed
// as it goes, written as markdown to CATGS_GPU_OUT at the end), and the helpers several topics use.
//
// Environment (scripts/gpu_run.sh sets it on the GPU machine; the legacy flags of catgs-gpu-tests,
// gpu_test_main.cpp, set the same variables):
//   CATGS_GPU_SCENES     folder of biker.compressed.ply, flowers_sh3.ply and
//                        tumblewood_sh2.compressed.ply (the compact copy .carry/scenes holds);
//                        default CATGS_DATA_DIR/scenes (then tumblewood_sh2.ply stands in for the
//                        compact copy, and the bundled biker for a missing one)
//   CATGS_GPU_TRACES     folder of the INRIA cameras.json files (default: CATGS_GPU_SCENES when
//                        that is set, else CATGS_DATA_DIR/traces)
//   CATGS_DATA_DIR       as for the unit tests (default: the build's, ../shared/data)
//   CATGS_GPU_QUICK=1    the quick sizes: 640x360 (hostile values 320x180), 48-frame catgs paths,
//                        4 yuv420 frames, abrupt motion on biker (ctest -L gpu_quick picks the
//                        quick subset)
//   CATGS_GPU_STRICT=1   a missing CUDA device or data file fails the test instead of skipping it
//   CATGS_GPU_OUT=F.md   the table of every row, written when the process ends
//   CATGS_GPU_ROWS=F     rows of every process that ran (ctest runs one a test), appended under a
//                        lock; CATGS_GPU_OUT then holds them all, in the tests' order
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "camera/trace.h"
#include "cpu/cpu_renderer.h"
#include "cuda/cuda_renderer.h"
#include "scene_tools/city.h"

namespace catgs::gputest {

using catgs::Camera;
using catgs::GaussianModel;
using catgs::Image;
using catgs::Pipeline;

// One line of the table: a check on one scene, view and pipeline.
struct Row {
  std::string test, scene, view, pipeline;
  double psnr = 0, max_abs = 0;
  int max_abs8 = 0;
  long long list_ref = -1, list_gpu = -1;
  bool pass = false;
  std::string note;
};

// Prints the row, keeps it for the table, and fails the running test when the row did not pass
// (the row's pass/fail criterion is the assertion).
void add(Row r);

struct Diff {
  double psnr, max_abs;
  int max_abs8;
};
Diff compare(const Image& a, const Image& b);
std::string fmt_psnr(double p);

// ---- configuration (the environment, read once) ----
struct Config {
  std::string scenes, traces;  // folders ("" when not found)
  bool quick = false;
  bool strict = false;
  int W = 1280, H = 720;  // 640x360 with quick
};
const Config& config();

// Path of a scene ("biker", "flowers_sh3", "tumblewood_sh2": the compact copy) or of a trace
// ("tandt_train", ...: TRACES/NAME.cameras.json); "" when absent.
std::string scene_path(const std::string& name);
std::string trace_path(const std::string& name);
// "" when every scene and trace named is there, else which one is missing and where it was looked
// for.
std::string missing(const std::vector<std::string>& scenes, const std::vector<std::string>& traces = {});
// "" when a CUDA device is usable, else why not (checked once).
std::string device_missing();
// The device's description ("" without one).
const std::string& gpu_name();

// The test fixture of every GPU test: skips (fails with CATGS_GPU_STRICT=1) without a usable
// CUDA device.
class GpuTest : public ::testing::Test {
 protected:
  void SetUp() override;
};

// ---- scenes, loaded once per process and shared (tests only read them) ----
struct SharedScene {
  std::shared_ptr<GaussianModel> model;
  std::shared_ptr<const catgs::cuda::DeviceScene> dev;
};
const SharedScene& biker();       // biker.compressed.ply
const SharedScene& flowers();     // flowers_sh3.ply
const SharedScene& tumblewood();  // tumblewood_sh2.compressed.ply x10, named "tumblewood_sh2"

std::shared_ptr<GaussianModel> load(const std::string& path, float scale);

// Four orbit views (0, 90, 180, 270 degrees) around the scene's robust bounds, world up -y.
std::vector<Camera> orbit_views(const GaussianModel& m, int w, int h);
// A real camera path moved onto `m` (tools/scene_tools/city.h) at 120 FPS, at most `frames` frames.
catgs::Trace real_trace(const GaussianModel& m, const std::string& cameras, int w, int h, std::size_t frames);
catgs::RenderOptions catgs_options();

// A scene of n huge, nearly opaque Gaussians stacked in front of the camera, each covering every
// tile of a 1920x1080 image (vanilla emits n * 8160 entries).
std::shared_ptr<GaussianModel> wall_scene(std::size_t n);
Camera front_camera(int w, int h);

// A budget of `limit` entries a pass at any size (min_entries alone sets it).
catgs::RenderListBudget pass_budget(std::uint64_t limit);

// The city of tumblewood copies within `radius_sq` cells of the centre (tools/scene_tools/city.h),
// and a fly-over camera over it with `flight`'s parameters at the tests' size.
struct TestCity {
  std::shared_ptr<GaussianModel> model;
  catgs::CityLayout layout;
  Camera view(const catgs::FlyoverParams& flight) const;
};
TestCity test_city(int radius_sq);

// The 13-copy city (test_city(4)) with its level of detail (lod/lod_build.h) on the device, and
// 96 frames of the real bicycle path over it at the tests' size; built once per process.
struct CityWithLod {
  std::shared_ptr<GaussianModel> lod;
  std::shared_ptr<const catgs::cuda::DeviceScene> dev;
  catgs::Trace trace;
};
const CityWithLod& city13_with_lod();

// Before RUN_ALL_TESTS (gpu_test_main.cpp): a test that fails without a failing row (an exception,
// a missing file or device with CATGS_GPU_STRICT=1) adds one, "gtest | SUITE | NAME | -".
void install_row_listener();

// At the end of the process (gpu_test_main.cpp): writes the table (CATGS_GPU_OUT, with
// CATGS_GPU_ROWS every process's rows) and prints "N checks: P passed, F failed" for this
// process's rows; returns F.
int finish_report();

}  // namespace catgs::gputest

// Skips the test (fails it with CATGS_GPU_STRICT=1) with a visible reason when `why` is not empty.
#define CATGS_GPU_SKIP_IF(why)                                     \
  do {                                                             \
    const std::string catgs_why_ = (why);                          \
    if (!catgs_why_.empty()) {                                     \
      if (::catgs::gputest::config().strict) FAIL() << catgs_why_; \
      GTEST_SKIP() << catgs_why_;                                  \
    }                                                              \
  } while (0)

// The scenes (first list) and traces (second) a test needs.
#define CATGS_GPU_REQUIRE(...) CATGS_GPU_SKIP_IF(::catgs::gputest::missing(__VA_ARGS__))
