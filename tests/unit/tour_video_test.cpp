// catgs-render --video (issue 38, item 1): the MP4 it writes, decoded by FFmpeg's own MP4 demuxer
// and H.264 decoder (libavformat, libavcodec; not our reader or our stream decoder), has the
// frame count, size, frame rate and duration asked for, and its frames match catgs-render's
// PNGs of the same poses. Bad input (a missing or malformed trace, a size past H.264's level
// limits, a path that cannot be written) fails before anything is rendered, with a clear error.
// Also: the H.264 level table, the progress line, and resampling a trace at the video's rate.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <glm/gtc/quaternion.hpp>

#include "camera/trace.h"
#include "common/image_io.h"
#include "common/progress.h"
#include "encode/h264_level.h"
#include "scene/scene_bounds.h"
#include "test_data.h"
#include "video_decode.h"

namespace {

using namespace catgs;
using test::catgs_render;
using test::decode_file;
using test::DecodedVideo;
using test::ToolRun;
namespace fs = std::filesystem;

// A short orbit around the bundled biker (test::biker_orbit) as a trace file.
std::string write_orbit(const std::string& dir, int frames, double rate, int width, int height) {
  const std::string path = dir + "/orbit.trace";
  write_trace(test::biker_orbit(frames, rate, width, height), path);
  return path;
}

constexpr int kW = 160, kH = 96, kFps = 24, kFrames = 18;

TEST(TourVideo, DecodedFileMatchesThePngs) {
  const std::string dir = test::temp_dir();
  const std::string trace = write_orbit(dir, kFrames, kFps, kW, kH);
  const std::string scene = " --scene " + test::bundled_scene() + " --trace " + trace;
  const std::string mp4 = dir + "/tour.mp4";
  const ToolRun video = catgs_render(scene + " --video " + mp4 + " --width " + std::to_string(kW) + " --height " +
                                         std::to_string(kH) + " --fps " + std::to_string(kFps),
                                     dir + "/video.log");
  ASSERT_EQ(video.status, 0) << video.output;
  // Not a terminal: plain progress lines, the last at 100%.
  EXPECT_NE(video.output.find("100% 18/18 frames"), std::string::npos) << video.output;
  EXPECT_EQ(video.output.find('\r'), std::string::npos) << "a redrawn bar in a log";
  const ToolRun pngs = catgs_render(scene + " --out-dir " + dir + "/png", dir + "/png.log");
  ASSERT_EQ(pngs.status, 0) << pngs.output;

  const DecodedVideo v = decode_file(mp4);
  EXPECT_EQ(v.codec, "h264");
  EXPECT_EQ(v.width, kW);
  EXPECT_EQ(v.height, kH);
  EXPECT_EQ(v.frame_rate.num, kFps * v.frame_rate.den);
  ASSERT_EQ(v.frames.size(), static_cast<std::size_t>(kFrames));
  EXPECT_NEAR(v.duration_s, static_cast<double>(kFrames) / kFps, 1e-6);
  EXPECT_TRUE(v.key[0]);
  // x264 picks the level itself; our table (which refuses sizes past 6.2) agrees with it.
  EXPECT_EQ(v.level, server::h264_level(kW, kH, kFps));
  double worst = 1e9;
  for (int k = 0; k < kFrames; ++k) {
    EXPECT_NEAR(v.times_s[static_cast<std::size_t>(k)], static_cast<double>(k) / kFps, 1e-6) << "frame " << k;
    char name[64];
    std::snprintf(name, sizeof name, "/png/frame_%05d.png", k);
    const double db = psnr_rgba8(read_png(dir + name), v.frames[static_cast<std::size_t>(k)]);
    worst = std::min(worst, db);
    EXPECT_GE(db, 35.0) << "frame " << k;
  }
  std::cout << "  " << kFrames << " frames " << kW << "x" << kH << " at " << kFps << " fps, " << fs::file_size(mp4)
            << " bytes; decoded frames vs the PNGs: worst " << worst << " dB\n";
  // A frame of another pose is far from it: the comparison tells poses apart.
  EXPECT_LT(psnr_rgba8(read_png(dir + "/png/frame_00000.png"), v.frames.back()), 30.0);
}

TEST(TourVideo, ResamplesTheTraceToTheVideoRate) {
  // A 24 Hz trace at 12 fps: every other camera, half the frames, the same duration.
  const std::string dir = test::temp_dir();
  const std::string trace = write_orbit(dir, 9, 24.0, 64, 48);
  const std::string mp4 = dir + "/half.mp4";
  const ToolRun r = catgs_render(
      "--scene " + test::bundled_scene() + " --trace " + trace + " --video " + mp4 + " --fps 12 --preset ultrafast",
      dir + "/log");
  ASSERT_EQ(r.status, 0) << r.output;
  const DecodedVideo v = decode_file(mp4);
  EXPECT_EQ(v.frames.size(), 5u);  // t = 0, 1/12, ..., 4/12 s: the trace's 8/24 s
  EXPECT_EQ(v.width, 64);          // the trace's own size
  EXPECT_NEAR(v.duration_s, 5.0 / 12.0, 1e-6);
}

// Bad input fails at once, names what is wrong, and leaves no file behind.
void expect_refused(const std::string& arguments, const std::string& dir, const std::string& says) {
  const ToolRun r = catgs_render("--scene " + test::bundled_scene() + " " + arguments, dir + "/bad.log");
  EXPECT_NE(r.status, 0) << arguments;
  EXPECT_NE(r.output.find(says), std::string::npos) << arguments << "\n" << r.output;
  EXPECT_EQ(r.output.find("scene biker"), std::string::npos) << "the scene loaded before the error: " << r.output;
}

TEST(TourVideo, BadInputGetsAClearError) {
  const std::string dir = test::temp_dir();
  const std::string trace = write_orbit(dir, 4, 24.0, 64, 48);
  const std::string out = " --video " + dir + "/x.mp4";
  expect_refused("--trace " + dir + "/missing.trace" + out, dir, dir + "/missing.trace: cannot open file");
  std::ofstream(dir + "/garbage.trace") << "catgs-trace 1\n0 1 2 3 not a pose\n";
  expect_refused("--trace " + dir + "/garbage.trace" + out, dir, dir + "/garbage.trace:2: expected 14 fields");
  std::ofstream(dir + "/empty.trace") << "catgs-trace 1\n# nothing\n";
  expect_refused("--trace " + dir + "/empty.trace" + out, dir, "the trace has no cameras");
  expect_refused("--trace " + trace + out + " --width 8192 --height 8192", dir,
                 "8192x8192 is too big for H.264 (level 6.2): 262144 macroblocks a frame, 139264 at most");
  expect_refused("--trace " + trace + out + " --width 7680 --height 4320 --fps 240", dir,
                 "is too fast for H.264 (level 6.2)");
  expect_refused("--trace " + trace + out + " --width 641 --height 480", dir, "must be even");
  expect_refused("--trace " + trace + " --video " + dir + "/no/such/folder/x.mp4", dir,
                 dir + "/no/such/folder/x.mp4: cannot open for writing");
  expect_refused("--trace " + trace + out + " --preset warpspeed", dir, "not an x264 preset: 'warpspeed'");
  // Two poses 10^7 s apart: 6 * 10^8 frames at 60 fps, refused before anything is allocated.
  std::ofstream(dir + "/long.trace") << "catgs-trace 1\n0 0 0 -5 1 0 0 0 50 50 32 24 64 48\n"
                                     << "10000000 0 0 -4 1 0 0 0 50 50 32 24 64 48\n";
  expect_refused("--trace " + dir + "/long.trace" + out, dir, "frames at 60 fps, more than --max-frames 216000");
  if (fs::is_character_file("/dev/full")) {  // a full disk; the device is not removed as a failed file
    expect_refused("--trace " + trace + " --video /dev/full", dir, "/dev/full: cannot write the MP4 header");
    EXPECT_TRUE(fs::is_character_file("/dev/full"));
  }
  EXPECT_FALSE(fs::exists(dir + "/x.mp4"));
}

// ---- the pieces ----

TEST(TourVideo, H264Levels) {
  EXPECT_EQ(server::h264_level(3840, 2160, 60), 52);
  EXPECT_EQ(server::h264_level(1920, 1080, 60), 42);
  EXPECT_EQ(server::h264_level(1920, 1080, 30), 40);
  EXPECT_EQ(server::h264_level(1280, 720, 30), 31);
  EXPECT_EQ(server::h264_level(176, 144, 15), 10);
  EXPECT_EQ(server::h264_level(8192, 4320, 60), 61);
  EXPECT_THROW(server::h264_level(8192, 8192, 1), std::invalid_argument);
  EXPECT_THROW(server::h264_level(16, 16896, 1), std::invalid_argument);  // a side past sqrt(8 MaxFS)
  EXPECT_EQ(server::h264_level(3840, 2160, 240), 61);
  EXPECT_THROW(server::h264_level(7680, 4320, 240), std::invalid_argument);  // 31 M macroblocks/s
  EXPECT_THROW(server::h264_level(0, 2160, 30), std::invalid_argument);
}

TEST(TourVideo, ProgressLine) {
  EXPECT_EQ(tools::Progress::line(45, 100, "frames", 15.0, false), " 45% 45/100 frames, 3.00 frames/s, 0:18 left");
  EXPECT_EQ(tools::Progress::line(10, 40, "frames", 5.0, true),
            "[=======>                      ]  25% 10/40 frames, 2.00 frames/s, 0:15 left");
  EXPECT_EQ(tools::Progress::line(0, 40, "frames", 0.0, false), "  0% 0/40 frames, 0.00 frames/s, ? left");
  EXPECT_EQ(tools::Progress::clock(3725.0), "1:02:05");
}

TEST(TourVideo, ResampleTrace) {
  GeneratorParams p;
  p.duration_s = 1.0;
  p.rate_hz = 8.0;
  p.width = 64;
  p.height = 48;
  const Trace t = make_orbit(Bounds{{-1, -1, -1}, {1, 1, 1}}, 4.0f, 0.5f, 90.0f, p);  // 9 cameras
  const Trace same = resample_trace(t, 8.0);
  ASSERT_EQ(same.size(), t.size());
  for (std::size_t i = 0; i < t.size(); ++i) EXPECT_EQ(same[i].camera.position(), t[i].camera.position());
  const Trace half = resample_trace(t, 4.0);
  ASSERT_EQ(half.size(), 5u);
  EXPECT_EQ(half[2].camera.position(), t[4].camera.position());
  // Between two cameras: halfway along the chord, the orientation halfway by angle.
  const Trace twice = resample_trace(t, 16.0);
  ASSERT_EQ(twice.size(), 17u);
  const glm::vec3 mid = 0.5f * (t[0].camera.position() + t[1].camera.position());
  EXPECT_LT(glm::distance(twice[1].camera.position(), mid), 1e-5f);
  const float a = glm::angle(glm::inverse(t[0].camera.orientation()) * twice[1].camera.orientation());
  const float b = glm::angle(glm::inverse(twice[1].camera.orientation()) * t[1].camera.orientation());
  EXPECT_NEAR(a, b, 1e-4f);
  EXPECT_THROW(resample_trace({}, 30.0), std::invalid_argument);
  EXPECT_THROW(resample_trace(t, 0.0), std::invalid_argument);
}

}  // namespace
