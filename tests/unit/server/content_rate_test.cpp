// Content-aware rate (encode/content_rate.h): the cap's bits a pixel from a probe of a scene's own
// moving frames. The probe's figure is checked by what it is for: a stream capped at the rate it
// chooses, decoded by libavcodec's own H.264 decoder (not x264), keeps the quality crf alone
// gives, while a cap well under it does not.
#include <gtest/gtest.h>

#include <iostream>
#include <vector>

#include "camera/camera.h"
#include "colour/yuv420.h"
#include "common/image_io.h"
#include "cpu/cpu_renderer.h"
#include "encode/content_rate.h"
#include "encode/x264_encoder.h"
#include "loadgen/video_decoder.h"
#include "process/first_view.h"
#include "server_options.h"
#include "test_data.h"

extern "C" {
#include <libavutil/log.h>
}

namespace {

const int kQuietLibav = (av_log_set_level(AV_LOG_ERROR), 0);

using namespace catgs;
using namespace catgs::server;

constexpr int kW = 320, kH = 192;

// The bundled biker panned sideways from the server's first view, `step` of the scene's scale a
// frame: every frame brings new pixels, as a visitor's moving camera does.
std::vector<Image> biker_pan(int frames, float step) {
  const auto model = test::cached_scene(test::bundled_scene());
  const SceneFrame scene = frame_from_content(*model);
  const CameraPose p = first_view_pose(scene, kW, kH);
  cpu::CpuRenderer renderer(model, RenderOptions{});
  std::vector<Image> out(static_cast<std::size_t>(frames));
  for (int k = 0; k < frames; ++k) {
    const glm::vec3 move(step * scene.scene_scale * static_cast<float>(k), 0.0f, 0.0f);
    renderer.render(Camera::from_pose(p.position + move, p.orientation, p.vertical_fov_deg, kW, kH), out[k]);
  }
  return out;
}

std::vector<Yuv420Image> to_yuv(const std::vector<Image>& frames) {
  std::vector<Yuv420Image> out(frames.size());
  for (std::size_t k = 0; k < frames.size(); ++k)
    out[k] = rgba_to_yuv420_bt709(frames[k].rgba8.data(), frames[k].width, frames[k].height, frames[k].width * 4);
  return out;
}

double probe_bpp(const std::vector<Yuv420Image>& frames, const std::string& preset = "superfast") {
  EncoderPolicy policy;
  ContentRateProbe probe(policy, kW, kH, 1, preset);
  for (const Yuv420Image& f : frames) probe.add(f.planes());
  EXPECT_TRUE(probe.done()) << frames.size() << " frames";
  return probe.crf_bits_per_pixel();
}

TEST(ContentRate, CapIsTheCrfRateWithHeadroomWithinBounds) {
  EXPECT_DOUBLE_EQ(content_bits_per_pixel(0.04), 0.04 * kContentHeadroom);
  EXPECT_DOUBLE_EQ(content_bits_per_pixel(0.001), kContentMinBitsPerPixel);
  EXPECT_DOUBLE_EQ(content_bits_per_pixel(0.5), kContentMaxBitsPerPixel);
  // The ceiling is the 12 Mbit/s for a 1080p60 stream.
  EXPECT_LE(kContentMaxBitsPerPixel * 1920 * 1080 * 60, 12.0e6);
}

TEST(ContentRate, ProbeCountsPFramesAndSeesMotion) {
  const std::vector<Image> pan = biker_pan(kProbeFrames + 1, 0.01f);
  const std::vector<Yuv420Image> moving = to_yuv(pan);
  // The probe takes its first picture as the IDR and counts the kProbeFrames after it.
  EncoderPolicy policy;
  ContentRateProbe probe(policy, kW, kH, 1, "superfast");
  for (std::size_t k = 0; k + 1 < moving.size(); ++k) probe.add(moving[k].planes());
  EXPECT_FALSE(probe.done());
  probe.add(moving.back().planes());
  EXPECT_TRUE(probe.done());
  const double pan_bpp = probe.crf_bits_per_pixel();
  // One picture over and over: P frames of nothing.
  const std::vector<Yuv420Image> still(kProbeFrames + 1, moving.front());
  const double still_bpp = probe_bpp(still);
  // A quicker pan brings more new pixels a frame.
  const double fast_bpp = probe_bpp(to_yuv(biker_pan(kProbeFrames + 1, 0.04f)));
  std::cout << "[ info ] crf 23 superfast bits a pixel: still " << still_bpp << ", pan " << pan_bpp << ", fast pan "
            << fast_bpp << "; ultrafast pan " << probe_bpp(moving, "ultrafast") << "\n";
  EXPECT_GT(pan_bpp, 0.0);
  EXPECT_LT(still_bpp * 4, pan_bpp);
  EXPECT_GT(fast_bpp, pan_bpp);
}

// The stream a session sends: superfast, crf 23 under a VBV cap of `kbps` (0: crf alone), 100 ms.
double stream_psnr(const std::vector<Image>& frames, const std::vector<Yuv420Image>& yuv, int kbps, double* rate) {
  EncoderConfig c;
  c.width = kW;
  c.height = kH;
  c.crf = 23;
  c.bitrate_kbps = kbps;
  c.vbv_buffer_ms = 100;
  c.threads = 1;
  c.x264_preset = "superfast";
  X264Encoder enc(c);
  loadgen::VideoDecoder dec("h264");
  double psnr = 0, bits = 0;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const EncodedFrame e = enc.encode_yuv420(yuv[k].planes(), false);
    if (k > 0) bits += 8.0 * static_cast<double>(e.data.size());
    Image out;
    EXPECT_TRUE(dec.decode(std::string(e.data.begin(), e.data.end()), out.rgba8, out.width, out.height));
    psnr += psnr_rgba8(out, frames[k]) / static_cast<double>(frames.size());
  }
  if (rate) *rate = bits * c.fps / static_cast<double>(frames.size() - 1) / 1000.0;
  return psnr;
}

TEST(ContentRate, ACapAtTheProbedRateKeepsCrfQuality) {
  // The probe sees the first frames of the pan; the streams run twice as long (as a session's
  // stream outlives its probe).
  const std::vector<Image> frames = biker_pan(2 * kProbeFrames, 0.01f);
  const std::vector<Yuv420Image> yuv = to_yuv(frames);
  const double crf_bpp = probe_bpp(std::vector<Yuv420Image>(yuv.begin(), yuv.begin() + kProbeFrames + 1));
  // The cap without the policy's clamp: at this small size the crf rate can sit under its floor.
  const int cap_kbps = static_cast<int>(crf_bpp * kContentHeadroom * kW * kH * 60 / 1000.0);
  double crf_rate = 0, cap_rate = 0, tight_rate = 0;
  const double crf_alone = stream_psnr(frames, yuv, 0, &crf_rate);
  const double capped = stream_psnr(frames, yuv, cap_kbps, &cap_rate);
  const double tight = stream_psnr(frames, yuv, cap_kbps / 4, &tight_rate);
  std::cout << "[ info ] crf 23 alone " << crf_alone << " dB at " << crf_rate << " kbit/s; cap " << cap_kbps
            << " kbit/s: " << capped << " dB at " << cap_rate << "; a quarter of it: " << tight << " dB at "
            << tight_rate << "\n";
  EXPECT_GT(crf_alone, 28.0);  // the scene, decoded
  EXPECT_GE(capped, crf_alone - 0.5);
  EXPECT_LT(tight, crf_alone - 1.0);
}

// --bits-per-pixel: a number as before (the probe off), auto for the probe, nothing else.
TEST(ContentRate, BitsPerPixelOption) {
  const char* none[] = {"catgs-server"};
  ServerOptions o0;
  ASSERT_TRUE(parse_server_options(1, const_cast<char**>(none), o0));
  EXPECT_FALSE(o0.session.frame.encoder_policy.content_rate);  // the default stays 0.09 (RESULTS.md)
  EXPECT_DOUBLE_EQ(o0.session.frame.encoder_policy.bits_per_pixel, 0.09);
  const char* fixed[] = {"catgs-server", "--bits-per-pixel", "0.05"};
  ServerOptions o1;
  ASSERT_TRUE(parse_server_options(3, const_cast<char**>(fixed), o1));
  EXPECT_FALSE(o1.session.frame.encoder_policy.content_rate);
  EXPECT_DOUBLE_EQ(o1.session.frame.encoder_policy.bits_per_pixel, 0.05);
  const char* probed[] = {"catgs-server", "--bits-per-pixel", "auto"};
  ServerOptions o2;
  ASSERT_TRUE(parse_server_options(3, const_cast<char**>(probed), o2));
  EXPECT_TRUE(o2.session.frame.encoder_policy.content_rate);
  const char* bad[] = {"catgs-server", "--bits-per-pixel", "lots"};
  ServerOptions o3;
  EXPECT_THROW((void)parse_server_options(3, const_cast<char**>(bad), o3), std::invalid_argument);
}

TEST(ContentRates, OneProbeASizeAndItsResultShared) {
  ContentRates rates;
  EXPECT_EQ(rates.bits_per_pixel(1280, 720), 0.0);
  EXPECT_TRUE(rates.claim(1280, 720));
  EXPECT_FALSE(rates.claim(1280, 720));  // another session measures it
  EXPECT_TRUE(rates.claim(1920, 1080));  // another size is another probe
  EXPECT_EQ(rates.bits_per_pixel(1280, 720), 0.0);
  rates.release(1920, 1080);  // that session left before its probe ended
  EXPECT_TRUE(rates.claim(1920, 1080));
  rates.set(1280, 720, 0.05);
  EXPECT_DOUBLE_EQ(rates.bits_per_pixel(1280, 720), 0.05);
  EXPECT_FALSE(rates.claim(1280, 720));  // measured
  rates.release(1280, 720);              // a result is not a claim: kept
  EXPECT_DOUBLE_EQ(rates.bits_per_pixel(1280, 720), 0.05);
}

}  // namespace
