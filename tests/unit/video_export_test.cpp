// The server's "Export video" (issue 38; session/video_export.h): a path sent as the page sends
// it (ExportVideoRequest), checked, and rendered frame by frame as background jobs on a render
// lane with the CPU core into an MP4 that FFmpeg's own demuxer and decoder read back with the
// frame count, size, rate and duration asked for, its frames matching catgs-render's PNGs of the
// same poses (>= 35 dB). The temporary file goes with its export, and start-up clears what an
// earlier run left.
#include <gtest/gtest.h>

#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>

#include "common/image_io.h"
#include "render/render_scheduler.h"
#include "session/video_export.h"
#include "test_data.h"
#include "video_decode.h"

namespace {

using namespace catgs;
using namespace catgs::server;
namespace fs = std::filesystem;

constexpr int kW = 160, kH = 90, kFps = 10, kPoses = 4;

// The request the page would send for `path`: its poses as the wire's 9 floats each.
pb::ExportVideoRequest request_for(const Trace& path) {
  pb::ExportVideoRequest r;
  r.set_export_id(3);
  r.set_width(kW);
  r.set_height(kH);
  r.set_fps(kFps);
  for (const TimedCamera& c : path) {
    const glm::vec3 p = c.camera.position();
    const glm::quat q = c.camera.orientation();
    const float fov = c.camera.vertical_fov_deg();
    for (float v : {static_cast<float>(c.time_s), p.x, p.y, p.z, q.w, q.x, q.y, q.z, fov}) r.add_path(v);
  }
  return r;
}

// Runs the export's steps as the session does: each frame a background job on the lanes that
// posts the next one. Returns the error of the step that failed, or "".
std::string run_on_lane(VideoExport& video) {
  RenderScheduler lanes;
  lanes.start(2, 1 << 20);
  std::mutex mutex;
  std::condition_variable ended;
  bool over = false;
  std::string error;
  std::function<void()> step = [&] {
    bool finished = false;
    try {
      finished = video.step();
    } catch (const std::exception& e) {
      error = e.what();
    }
    std::lock_guard<std::mutex> lock(mutex);
    if (finished || !error.empty()) {
      over = true;
      ended.notify_all();
    } else {
      lanes.post_background(1, video.pixels(), step);
    }
  };
  lanes.post_background(1, video.pixels(), step);
  std::unique_lock<std::mutex> lock(mutex);
  ended.wait_for(lock, std::chrono::seconds(120), [&] { return over; });
  lock.unlock();
  lanes.stop();
  return over ? error : "timed out";
}

TEST(VideoExport, DecodedFileMatchesCatgsRenderPngs) {
  const std::string dir = test::temp_dir();
  // 4 poses 0.5 s apart along an orbit: 1.5 s of path, 16 frames at 10 fps, each between two poses.
  const Trace path = test::biker_orbit(kPoses, 2.0, kW, kH);
  ExportPlan plan;
  ASSERT_FALSE(check_export_request(request_for(path), ExportLimits{}, plan).has_value());
  ASSERT_EQ(plan.frames.size(), 16u);

  std::string file;
  {
    VideoExport video(plan, test::cached_scene(test::bundled_scene()), "cpu", RenderOptions{}, 0, 1, dir);
    file = video.path();
    EXPECT_EQ(fs::path(file).parent_path(), fs::path(dir));
    EXPECT_EQ(fs::path(file).filename().string().rfind("catgs-export-", 0), 0u);
    ASSERT_EQ(run_on_lane(video), "");
    EXPECT_EQ(video.frames_done(), 16);
    ASSERT_TRUE(fs::exists(file));
    fs::copy_file(file, dir + "/kept.mp4");
  }
  EXPECT_FALSE(fs::exists(file)) << "the export's file outlived it";

  // The same frames through catgs-render: the plan's cameras as a trace, one PNG each.
  write_trace(plan.frames, dir + "/frames.trace");
  const test::ToolRun pngs = test::catgs_render(
      "--scene " + test::bundled_scene() + " --trace " + dir + "/frames.trace --out-dir " + dir + "/png",
      dir + "/png.log");
  ASSERT_EQ(pngs.status, 0) << pngs.output;

  const test::DecodedVideo v = test::decode_file(dir + "/kept.mp4");
  EXPECT_EQ(v.codec, "h264");
  EXPECT_EQ(v.width, kW);
  EXPECT_EQ(v.height, kH);
  EXPECT_EQ(v.frame_rate.num, kFps * v.frame_rate.den);
  ASSERT_EQ(v.frames.size(), 16u);
  EXPECT_NEAR(v.duration_s, 1.6, 1e-6);
  double worst = 1e9;
  for (std::size_t k = 0; k < v.frames.size(); ++k) {
    char name[64];
    std::snprintf(name, sizeof name, "/png/frame_%05d.png", static_cast<int>(k));
    const double db = psnr_rgba8(read_png(dir + name), v.frames[k]);
    worst = std::min(worst, db);
    EXPECT_GE(db, 35.0) << "frame " << k;
  }
  std::cout << "  16 frames " << kW << "x" << kH << " at " << kFps << " fps, " << fs::file_size(dir + "/kept.mp4")
            << " bytes; decoded frames vs catgs-render's PNGs: worst " << worst << " dB\n";
  // The comparison tells poses apart: the last frame is far from the first PNG.
  EXPECT_LT(psnr_rgba8(read_png(dir + "/png/frame_00000.png"), v.frames.back()), 30.0);
}

TEST(VideoExport, CancelStopsAndDeletesTheFile) {
  const std::string dir = test::temp_dir();
  ExportPlan plan;
  ASSERT_FALSE(
      check_export_request(request_for(test::biker_orbit(kPoses, 2.0, kW, kH)), ExportLimits{}, plan).has_value());
  std::string file;
  {
    VideoExport video(plan, test::cached_scene(test::bundled_scene()), "cpu", RenderOptions{}, 0, 1, dir);
    file = video.path();
    EXPECT_FALSE(video.step());
    EXPECT_EQ(video.frames_done(), 1);
    EXPECT_TRUE(fs::exists(file)) << "the file is opened by the first step";
    video.cancel();
    EXPECT_FALSE(video.step());
    EXPECT_EQ(video.frames_done(), 1) << "a cancelled export rendered on";
  }
  EXPECT_FALSE(fs::exists(file)) << "a cancelled export's file outlived it";
}

TEST(VideoExport, StartUpRemovesOnlyStaleExports) {
  const std::string dir = test::temp_dir() + "/exports";
  EXPECT_EQ(export_folder(dir), dir);
  EXPECT_TRUE(fs::is_directory(dir));
  std::ofstream(dir + "/catgs-export-0123abcd.mp4") << "left by a killed server";
  std::ofstream(dir + "/catgs-export-notes.txt") << "not ours";
  std::ofstream(dir + "/holiday.mp4") << "not ours";
  EXPECT_EQ(remove_stale_exports(dir), 1);
  EXPECT_FALSE(fs::exists(dir + "/catgs-export-0123abcd.mp4"));
  EXPECT_TRUE(fs::exists(dir + "/catgs-export-notes.txt"));
  EXPECT_TRUE(fs::exists(dir + "/holiday.mp4"));
  std::ofstream(dir + "/file") << "x";
  EXPECT_THROW(export_folder(dir + "/file"), std::runtime_error);
  EXPECT_TRUE(video_export_built());
}

}  // namespace
