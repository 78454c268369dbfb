// The encoder policy (encode/encoder_policy.h) and what x264 makes of it: the target bitrate by
// viewport with the client's cap, threads shared among live sessions, the rebuild rule, and on
// real renders of the bundled scene: a capped stream holds its cap, sliced threads give one
// access unit a frame with a slice per thread, intra refresh leaves the first IDR the only one.
// Streams are checked by libavcodec's h264 decoder and by reading their NAL unit types.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <iostream>
#include <vector>

#include "common/image_io.h"
#include "camera/camera.h"
#include "cpu/cpu_renderer.h"
#include "encode/encoder_policy.h"
#include "encode/x264_encoder.h"
#include "loadgen/video_decoder.h"
#include "process/first_view.h"
#include "test_data.h"

extern "C" {
#include <libavutil/log.h>
}

namespace {

const int kQuietLibav = (av_log_set_level(AV_LOG_ERROR), 0);

using namespace catgs;
using namespace catgs::server;

TEST(EncoderPolicy, TargetBitrateFollowsTheViewportAndTheClientCap) {
  EncoderPolicy p;                                              // auto, 0.09 bits a pixel, floor 1500 kbit/s
  EXPECT_EQ(target_bitrate_kbps(p, 1920, 1080, 60, 0), 11197);  // 0.09 x 1920 x 1080 x 60 / 1000
  EXPECT_EQ(target_bitrate_kbps(p, 1280, 720, 60, 0), 4977);
  EXPECT_EQ(target_bitrate_kbps(p, 640, 360, 60, 0), 1500);         // the floor
  EXPECT_EQ(target_bitrate_kbps(p, 1920, 1080, 60, 3000), 3000);    // a client's cap lowers it
  EXPECT_EQ(target_bitrate_kbps(p, 1920, 1080, 60, 50000), 11197);  // but never raises it
  p.bitrate_kbps = 0;                                               // off: crf alone unless the client caps it
  EXPECT_EQ(target_bitrate_kbps(p, 1920, 1080, 60, 0), 0);
  EXPECT_EQ(target_bitrate_kbps(p, 1920, 1080, 60, 2500), 2500);
  p.bitrate_kbps = 8000;
  EXPECT_EQ(target_bitrate_kbps(p, 640, 360, 60, 0), 8000);
}

TEST(EncoderPolicy, ThreadsShareTheCoresAmongLiveSessions) {
  EncoderPolicy p;
  p.usable_cores = 16;
  EXPECT_EQ(encoder_threads(p, 1920, 1080, 1), useful_threads(1920, 1080));
  EXPECT_EQ(encoder_threads(p, 1920, 1080, 8), 4);  // twice the cores, shared
  EXPECT_EQ(encoder_threads(p, 1920, 1080, 10), 3);
  EXPECT_EQ(encoder_threads(p, 1920, 1080, 40), 2);  // what 1080p needs for 60 frames/s
  EXPECT_EQ(encoder_threads(p, 1280, 720, 40), 1);
  EXPECT_EQ(needed_threads(1280, 720), 1);
  EXPECT_EQ(needed_threads(1920, 1080), 2);
  EXPECT_EQ(needed_threads(3840, 2160), 6);
  EXPECT_EQ(encoder_threads(p, 640, 360, 1), useful_threads(640, 360));
  EXPECT_LE(useful_threads(640, 360), useful_threads(1280, 720));
  EXPECT_LE(useful_threads(1280, 720), useful_threads(1920, 1080));
  p.threads = 3;  // --encoder-threads 3: fixed
  EXPECT_EQ(encoder_threads(p, 1920, 1080, 20), 3);
  const EncoderConfig c = encoder_config(EncoderPolicy{}, 1280, 720, 60, 1, 0);
  EXPECT_EQ(c.width, 1280);
  EXPECT_EQ(c.bitrate_kbps, 4977);
  EXPECT_EQ(c.crf, EncoderPolicy{}.crf);
}

TEST(EncoderPolicy, FewerThreadsAtOnceMoreOnlyAfterTheGrowDelay) {
  using std::chrono::seconds;
  EXPECT_TRUE(should_rebuild(8, 4, seconds(0)));  // sessions joined
  EXPECT_FALSE(should_rebuild(4, 4, seconds(100)));
  EXPECT_FALSE(should_rebuild(4, 8, seconds(1)));  // sessions left a moment ago
  EXPECT_TRUE(should_rebuild(4, 8, kGrowDelay));
}

// Frames of the bundled biker along a short orbit around the server's first view (moving content).
std::vector<Yuv420Image> biker_frames(int w, int h, int n, std::vector<Image>* raw = nullptr) {
  auto model = test::cached_scene(test::bundled_scene());
  const SceneFrame frame = frame_from_content(*model);
  const CameraPose p = first_view_pose(frame, w, h);
  cpu::CpuRenderer renderer(model, RenderOptions{});
  std::vector<Yuv420Image> out;
  for (int k = 0; k < n; ++k) {
    const glm::quat turn = glm::angleAxis(glm::radians(0.6f * static_cast<float>(k)), frame.up);
    const glm::vec3 pos = frame.orbit_centre + turn * (p.position - frame.orbit_centre);
    Image img;
    renderer.render(Camera::from_pose(pos, turn * p.orientation, p.vertical_fov_deg, w, h), img);
    out.push_back(rgba_to_yuv420_bt709(img.rgba8.data(), w, h, w * 4));
    if (raw) raw->push_back(std::move(img));
  }
  return out;
}

// NAL unit types of an Annex B access unit, in order.
std::vector<int> nal_types(const std::vector<std::uint8_t>& au) {
  std::vector<int> types;
  for (std::size_t i = 0; i + 3 < au.size(); ++i)
    if (au[i] == 0 && au[i + 1] == 0 && au[i + 2] == 1) {
      types.push_back(au[i + 3] & 0x1f);
      i += 3;
    }
  return types;
}

int count(const std::vector<int>& v, int x) { return static_cast<int>(std::count(v.begin(), v.end(), x)); }

// A width x height x264 config at the policy's defaults but no rate cap (crf 23 alone).
EncoderConfig small_config(int w, int h) {
  EncoderConfig c;
  c.width = w;
  c.height = h;
  return c;
}

struct Stream {
  std::vector<EncodedFrame> frames;
  double mean_kbps = 0;
  double mean_psnr = 0;
};

Stream encode_all(const EncoderConfig& c, const std::vector<Yuv420Image>& frames, const std::vector<Image>& raw) {
  X264Encoder enc(c);
  loadgen::VideoDecoder dec;
  Stream s;
  double bytes = 0;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    s.frames.push_back(enc.encode_yuv420(frames[k].planes(), false));
    bytes += static_cast<double>(s.frames.back().data.size());
    Image d;
    EXPECT_TRUE(
        dec.decode(std::string(s.frames.back().data.begin(), s.frames.back().data.end()), d.rgba8, d.width, d.height))
        << "frame " << k;
    s.mean_psnr += psnr_rgba8(d, raw[k]) / static_cast<double>(frames.size());
  }
  s.mean_kbps = bytes * 8 * c.fps / static_cast<double>(frames.size()) / 1000;
  return s;
}

TEST(EncoderPolicy, CappedStreamHoldsItsCapAndCrfIsItsFloor) {
  std::vector<Image> raw;
  const auto frames = biker_frames(320, 192, 48, &raw);
  EncoderConfig c = small_config(320, 192);
  c.crf = 12;  // more bits than the cap allows on this moving view
  const Stream free = encode_all(c, frames, raw);
  c.bitrate_kbps = std::max(200, static_cast<int>(free.mean_kbps / 4));
  c.vbv_buffer_ms = 100;
  const Stream capped = encode_all(c, frames, raw);
  // The VBV may overshoot by at most its buffer over the run: 100 ms of 48 frames / 60 fps.
  EXPECT_LE(capped.mean_kbps, c.bitrate_kbps * (1 + 0.1 / 0.8) + 1) << "uncapped " << free.mean_kbps;
  EXPECT_LT(capped.mean_psnr, free.mean_psnr);
  EXPECT_GT(capped.mean_psnr, 25.0);  // still the scene
  // A cap far above what crf needs changes nothing: crf is the floor of the quality.
  c.bitrate_kbps = static_cast<int>(free.mean_kbps * 20);
  const Stream loose = encode_all(c, frames, raw);
  EXPECT_NEAR(loose.mean_kbps, free.mean_kbps, free.mean_kbps * 0.02);
}

// The ladder by hand: half of 16 cores is 8000 CPU ms a second; ultrafast at 1080p takes 7.7 ms
// a megapixel x 2.07 MP x 60 frames = 958 ms a second a session, superfast 2.3x that (2204: three
// sessions fit, four do not). At 720p 426 a session, superfast 980: eight fit, nine do not.
TEST(EncoderPolicy, PresetLadderSpendsTheEncodersShareOfTheCores) {
  EncoderPolicy p;
  p.usable_cores = 16;
  const auto preset = [&](int w, int h, int live) { return encoder_preset(p, w, h, 60, live); };
  // 8000 CPU ms a second for the encoders; ultrafast costs 958 ms a second a 1080p session, 426
  // a 720p one; the middle step 1.4x that, superfast 2.3x.
  for (int live : {1, 3}) EXPECT_EQ(preset(1920, 1080, live), "superfast") << live;
  for (int live : {4, 5}) EXPECT_EQ(preset(1920, 1080, live), "ultrafast+cabac+deblock") << live;
  for (int live : {6, 9, 40}) EXPECT_EQ(preset(1920, 1080, live), "ultrafast") << live;
  EXPECT_EQ(preset(1280, 720, 8), "superfast");
  EXPECT_EQ(preset(1280, 720, 9), "ultrafast+cabac+deblock");
  EXPECT_EQ(preset(1280, 720, 13), "ultrafast+cabac+deblock");
  EXPECT_EQ(preset(1280, 720, 14), "ultrafast");
  // Never a slower step for more sessions, at any size.
  for (const auto& [w, h] : {std::pair{640, 360}, std::pair{1280, 720}, std::pair{1920, 1080}, std::pair{3840, 2160}})
    for (int live = 1; live < 64; ++live)
      EXPECT_LE(preset_step(p, w, h, 60, live + 1), preset_step(p, w, h, 60, live)) << w << "x" << h << " " << live;
  // Two cores (the build machine) afford no more than ultrafast at 1080p, even alone.
  p.usable_cores = 2;
  EXPECT_EQ(preset(1920, 1080, 1), "ultrafast");
  // --x264-preset NAME wins; the config carries the choice.
  p.usable_cores = 16;
  EXPECT_EQ(encoder_config(p, 1920, 1080, 60, 1, 0).x264_preset, "superfast");
  p.x264_preset = "faster";
  EXPECT_EQ(encoder_config(p, 1920, 1080, 60, 1, 0).x264_preset, "faster");
  EXPECT_TRUE(is_x264_preset("superfast"));
  EXPECT_FALSE(is_x264_preset("auto"));
  EXPECT_FALSE(is_x264_preset("ultrafast "));
}

// --x264-floor by hand, 16 cores (8000 CPU ms a second for the encoders), 720p at 60 frames/s:
// ultrafast 7.0963 ms a frame, 425.8 CPU ms a second a session; ultrafast+cabac+deblock 1.4x
// (596.1): 13 sessions fit, 14 do not; superfast 2.3x (979.3): 8 fit, 9 do not.
TEST(EncoderPolicy, TheFloorHoldsTheLadderAndTheDoorCountsTheCores) {
  EncoderPolicy p;
  p.usable_cores = 16;
  EXPECT_TRUE(cores_hold(p, 1280, 720, 60, 1000)) << "no floor: the door does not count the cores";
  EXPECT_EQ(preset_step(p, 1280, 720, 60, 20), 0);
  p.floor_step = ladder_step_named("ultrafast+cabac+deblock");
  EXPECT_EQ(p.floor_step, 1);
  EXPECT_TRUE(cores_hold(p, 1280, 720, 60, 13));
  EXPECT_FALSE(cores_hold(p, 1280, 720, 60, 14));
  EXPECT_EQ(preset_step(p, 1280, 720, 60, 13), 1);
  EXPECT_EQ(preset_step(p, 1280, 720, 60, 20), 1) << "never below the floor (a session the door let in, resized)";
  EXPECT_EQ(preset_step(p, 1280, 720, 60, 8), 2);
  p.floor_step = ladder_step_named("superfast");
  EXPECT_TRUE(cores_hold(p, 1280, 720, 60, 8));
  EXPECT_FALSE(cores_hold(p, 1280, 720, 60, 9));
  p.x264_preset = "ultrafast";
  EXPECT_TRUE(cores_hold(p, 1280, 720, 60, 9)) << "a fixed preset: no ladder, no floor";
  EXPECT_EQ(ladder_step_named("off"), -1);
  EXPECT_THROW(ladder_step_named("veryfast"), std::invalid_argument);
}

// AV1 by hand, 16 cores (8000 CPU ms a second for the encoders), 60 frames/s (10 ms is 0.6 of
// the interval). 960x540: ultrafast 3.99 ms a frame, AV1 8x that = 31.9 ms on one thread, 6.8 ms
// on 8 (speed-up 4.7) and 1916 CPU ms a second a session: four fit, five do not. 640x360: 1.77
// ms, 851.6 a second: nine fit, ten do not (6.9 ms a frame on their 3 threads). 720p: 56.8 ms /
// 4.7 = 12.1 ms a frame on 8 threads: never at 60 frames/s, nor 1080p (27.2 ms); at 30 frames/s
// (20 ms) 720p fits, four sessions by the cores (3406 CPU ms a second a session at 60).
TEST(EncoderPolicy, Av1OnlyForClientsThatDecodeItWhileTheCoresAffordIt) {
  EncoderPolicy p;
  p.usable_cores = 16;
  const auto av1 = [&](int w, int h, int live) { return use_av1(p, w, h, 60, live, true, true, false); };
  EXPECT_NEAR(av1_frame_ms(960, 540, 8), 7.7e-6 * 960 * 540 * 8 / 4.7, 1e-9);
  EXPECT_NEAR(av1_frame_ms(960, 540, 4), 7.7e-6 * 960 * 540 * 8 / (1 + 3.7 * 3 / 7), 1e-9);
  EXPECT_NEAR(av1_frame_ms(960, 540, 1), 7.7e-6 * 960 * 540 * 8, 1e-9);
  EXPECT_TRUE(av1(960, 540, 1));
  EXPECT_TRUE(av1(960, 540, 4));
  EXPECT_FALSE(av1(960, 540, 5));
  EXPECT_TRUE(av1(640, 360, 9));
  EXPECT_FALSE(av1(640, 360, 10));
  EXPECT_FALSE(av1(1280, 720, 1)) << "a frame would take 12 ms, over 0.6 of the 16.7 ms interval";
  EXPECT_FALSE(av1(1920, 1080, 1)) << "a frame would take 27 ms of a 16.7 ms interval";
  EXPECT_TRUE(use_av1(p, 1280, 720, 30, 4, true, true, false)) << "at 30 frames/s four 720p sessions fit";
  // Never AV1 for more sessions once a count is refused, at any size.
  for (const auto& [w, h] : {std::pair{640, 360}, std::pair{960, 540}, std::pair{1280, 720}})
    for (int live = 1; live < 64; ++live)
      EXPECT_LE(av1(w, h, live + 1), av1(w, h, live)) << w << "x" << h << " " << live;
  // A client that does not list it, an NVENC host, a link that limits the stream: H.264.
  EXPECT_FALSE(use_av1(p, 640, 360, 60, 1, false, true, false));
  EXPECT_FALSE(use_av1(p, 640, 360, 60, 1, true, false, false));
  EXPECT_FALSE(use_av1(p, 640, 360, 60, 1, true, true, true));
  // --av1 on: whatever the count and size; off: never.
  p.av1 = "on";
  EXPECT_TRUE(av1(1920, 1080, 40));
  EXPECT_FALSE(use_av1(p, 1920, 1080, 60, 1, true, true, true)) << "a limiting link still leaves AV1";
  p.av1 = "off";
  EXPECT_FALSE(av1(640, 360, 1));
}

// What the ladder buys: at the same capped rate on real renders, each slower step of the ladder
// decodes (libavcodec) to at least its faster neighbour's PSNR against the raw render, and the
// slowest to more than ultrafast's.
TEST(EncoderPolicy, SlowerPresetsGiveMoreQualityAtTheSameRate) {
  std::vector<Image> raw;
  const auto frames = biker_frames(320, 192, 48, &raw);
  EncoderConfig c = small_config(320, 192);
  c.crf = 12;            // a floor above what the cap allows: every preset spends the whole cap
  c.bitrate_kbps = 250;  // and the preset decides the quality
  c.vbv_buffer_ms = 100;
  std::vector<double> psnr;
  for (const PresetStep& step : kPresetLadder) {
    c.x264_preset = step.name;
    const Stream s = encode_all(c, frames, raw);
    EXPECT_LE(s.mean_kbps, c.bitrate_kbps * (1 + 0.1 / 0.8) + 1) << step.name;
    EXPECT_GE(s.mean_kbps, c.bitrate_kbps * 0.8) << step.name << ": under the cap, crf not the floor";
    psnr.push_back(s.mean_psnr);
    std::cout << "  " << step.name << ": " << s.mean_psnr << " dB at " << s.mean_kbps << " kbit/s\n";
  }
  for (std::size_t k = 1; k < psnr.size(); ++k) EXPECT_GE(psnr[k], psnr[k - 1] - 0.1) << kPresetLadder[k].name;
  EXPECT_GT(psnr.back(), psnr.front());
}

TEST(EncoderPolicy, SlicedThreadsGiveEveryFrameAtOnceWithASlicePerThread) {
  std::vector<Image> raw;
  const auto frames = biker_frames(640, 352, 6, &raw);
  for (int threads : {1, 4}) {
    SCOPED_TRACE(threads);
    EncoderConfig c = small_config(640, 352);
    c.threads = threads;
    const Stream s = encode_all(c, frames, raw);  // encode_yuv420 throws on a frame of delay
    ASSERT_EQ(s.frames.size(), frames.size());
    EXPECT_EQ(count(nal_types(s.frames[0].data), 5), threads);  // IDR slices
    EXPECT_EQ(count(nal_types(s.frames[3].data), 1), threads);  // P slices
    EXPECT_GT(s.mean_psnr, 30.0);
  }
}

TEST(EncoderPolicy, IntraRefreshSendsNoIdrAfterTheFirstUnlessForced) {
  std::vector<Image> raw;
  const auto frames = biker_frames(320, 192, 40, &raw);
  EncoderConfig c = small_config(320, 192);
  c.intra_refresh_frames = 10;  // four refresh waves in 40 frames
  const Stream s = encode_all(c, frames, raw);
  EXPECT_GT(count(nal_types(s.frames[0].data), 5), 0);
  std::size_t largest_later = 0;
  for (std::size_t k = 1; k < s.frames.size(); ++k) {
    EXPECT_EQ(count(nal_types(s.frames[k].data), 5), 0) << "frame " << k;
    largest_later = std::max(largest_later, s.frames[k].data.size());
  }
  // Without refresh (the default) a forced IDR is one intra picture; with it, no later frame is
  // that large: the intra blocks are spread over the period.
  EXPECT_LT(largest_later, s.frames[0].data.size());
  X264Encoder enc(c);
  enc.encode_yuv420(frames[0].planes(), false);
  enc.encode_yuv420(frames[1].planes(), false);
  EXPECT_GT(count(nal_types(enc.encode_yuv420(frames[2].planes(), true).data), 5), 0);  // a KeyFrameRequest
}

// A preset with tools turned back on (encoder_policy.h): the names parse, and the stream says so
// itself: the picture parameter set's entropy_coding_mode_flag (H.264 7.3.2.2: after two ue(v)
// ids, 0 and 0 here, each the single bit 1) is set with +cabac and clear for plain ultrafast.
TEST(EncoderPolicy, PresetWithToolsTurnedBackOn) {
  EXPECT_EQ(parse_x264_preset("ultrafast").params, "");
  EXPECT_EQ(parse_x264_preset("ultrafast+cabac+deblock").preset, "ultrafast");
  EXPECT_EQ(parse_x264_preset("ultrafast+cabac+deblock").params, "cabac=1:deblock=1");
  EXPECT_EQ(parse_x264_preset("superfast+deblock").params, "deblock=1");
  EXPECT_TRUE(is_x264_preset("ultrafast+deblock"));
  EXPECT_FALSE(is_x264_preset("ultrafast+cabac+cabac"));
  EXPECT_FALSE(is_x264_preset("ultrafast+trellis"));
  EXPECT_FALSE(is_x264_preset("+cabac"));
  EXPECT_FALSE(is_x264_preset("ultrafast+"));
  std::vector<Image> raw;
  const auto frames = biker_frames(320, 192, 4, &raw);
  for (const std::string preset : {"ultrafast", "ultrafast+cabac", "ultrafast+cabac+deblock"}) {
    EncoderConfig c = small_config(320, 192);
    c.x264_preset = preset;
    const Stream s = encode_all(c, frames, raw);
    const std::vector<std::uint8_t>& d = s.frames[0].data;
    int flag = -1;
    for (std::size_t k = 0; k + 4 < d.size(); ++k)
      if (d[k] == 0 && d[k + 1] == 0 && d[k + 2] == 1 && (d[k + 3] & 0x1f) == 8) {  // a PPS
        ASSERT_EQ(d[k + 4] >> 6, 3) << "ids other than 0";
        flag = (d[k + 4] >> 5) & 1;
        break;
      }
    EXPECT_EQ(flag, preset == "ultrafast" ? 0 : 1) << preset;
    EXPECT_GT(s.mean_psnr, 30.0) << preset;
  }
}

}  // namespace
