// A frame's encoder settings in one call (encode/frame_encoding.h), worked by hand from the
// policy's rules (encoder_policy.h): auto's 0.09 bits a pixel at 60 frames/s, the client's and the
// link's caps (the lower wins), the link's two-frame VBV, the probed bits a pixel, AV1 only where
// the cores afford it and the link does not limit, and the refine frame's lifted cap.
#include <gtest/gtest.h>

#include "encode/frame_encoding.h"

namespace {

using namespace catgs::server;

EncoderPolicy sixteen_cores() {
  EncoderPolicy p;
  p.usable_cores = 16;
  return p;
}

FrameEncodeInputs frame(int w, int h) {
  FrameEncodeInputs in;
  in.width = w;
  in.height = h;
  return in;
}

// A link that limits the stream at `cap_kbps` on the wire, carrying 60 frames a second, an
// encoder that sends what it is asked.
LinkInputs limiting_link(double cap_kbps, double frame_rate = 60.0, double gain = 1.0) {
  LinkInputs l;
  l.limiting = true;
  l.cap_kbps = cap_kbps;
  l.frame_rate = frame_rate;
  l.encoder_gain = gain;
  return l;
}

// The link's share (issue 75: frame_encoding takes the link's state, once a frame): the ceiling is
// the policy's rate times the frames a second the link carries over 60 (at least 10 frames'
// share), the encoder's cap the link's cap under that ceiling, over the same share, times the
// encoder's gain.
TEST(FrameEncoding, TheLinksShareOfTheRateFollowsItsFrameRate) {
  const EncoderPolicy p = sixteen_cores();
  FrameEncodeInputs in = frame(1920, 1080);
  FrameEncoding e = frame_encoding(p, in);
  EXPECT_EQ(e.link_ceiling_kbps, 11197 * 10 / 60) << "no frame rate measured yet: the 10 frames' floor";
  EXPECT_EQ(e.link_kbps, 0) << "a link that does not limit";
  in.link.frame_rate = 30;
  EXPECT_EQ(frame_encoding(p, in).link_ceiling_kbps, 11197 / 2);
  in.link = limiting_link(3000, 30);
  e = frame_encoding(p, in);
  EXPECT_EQ(e.link_kbps, 6000) << "3000 kbit/s at 30 frames/s: each frame the share of 60 frames'";
  EXPECT_EQ(e.rate_kbps, 6000);
  in.link = limiting_link(9000, 30);
  EXPECT_EQ(frame_encoding(p, in).link_kbps, 11196) << "the cap under the ceiling (5598), over the share";
  in.link = limiting_link(3000, 60, 0.8);
  EXPECT_EQ(frame_encoding(p, in).link_kbps, 2400) << "an encoder that overshoots is asked for less";
  in.link = limiting_link(1000, 2);
  EXPECT_EQ(frame_encoding(p, in).link_kbps, 6000) << "a jammed link at 2 frames/s: the 10 frames' share, not 2";
  in.client_max_kbps = 1200;
  EXPECT_EQ(frame_encoding(p, in).link_ceiling_kbps, 200) << "the client's cap lowers the ceiling too";
}

TEST(FrameEncoding, CapsLowerTheRateAndTheLinkShrinksTheVbv) {
  const EncoderPolicy p = sixteen_cores();
  FrameEncodeInputs in = frame(1920, 1080);
  FrameEncoding e = frame_encoding(p, in);
  EXPECT_EQ(e.rate_kbps, 11197);  // 0.09 x 1920 x 1080 x 60 / 1000 = 11197.4, rounded
  EXPECT_EQ(e.vbv_ms, p.vbv_buffer_ms);
  in.client_max_kbps = 5000;
  EXPECT_EQ(frame_encoding(p, in).rate_kbps, 5000);
  EXPECT_EQ(frame_encoding(p, in).vbv_ms, p.vbv_buffer_ms) << "a client's cap keeps the policy's buffer";
  in.link = limiting_link(3000);
  e = frame_encoding(p, in);
  EXPECT_EQ(e.rate_kbps, 3000) << "the lower of the client's and the link's";
  EXPECT_EQ(e.vbv_ms, 33) << "two frames at 60 frames/s while the link limits";
  in.client_max_kbps = 2000;
  EXPECT_EQ(frame_encoding(p, in).rate_kbps, 2000);
  in.client_max_kbps = 50000;
  in.link = {};
  EXPECT_EQ(frame_encoding(p, in).rate_kbps, 11197) << "a cap never raises the rate";
}

TEST(FrameEncoding, ProbedBitsAPixelCountOnlyWithContentRateOn) {
  EncoderPolicy p = sixteen_cores();
  FrameEncodeInputs in = frame(1920, 1080);
  in.probed_bits_per_pixel = 0.045;
  EXPECT_EQ(frame_encoding(p, in).rate_kbps, 11197) << "--bits-per-pixel auto is off";
  p.content_rate = true;
  const FrameEncoding e = frame_encoding(p, in);
  EXPECT_EQ(e.rate_kbps, 5599);  // 0.045 x 1920 x 1080 x 60 / 1000 = 5598.7, rounded
  EXPECT_DOUBLE_EQ(e.policy.bits_per_pixel, 0.045);
  in.probed_bits_per_pixel = 0;  // no probe yet: the policy's own
  EXPECT_EQ(frame_encoding(p, in).rate_kbps, 11197);
}

TEST(FrameEncoding, TheConfigCarriesTheSameDecision) {
  const EncoderPolicy p = sixteen_cores();
  FrameEncodeInputs in = frame(1280, 720);
  in.live_sessions = 9;
  in.link = limiting_link(2500);
  const FrameEncoding e = frame_encoding(p, in);
  EXPECT_EQ(e.preset, "ultrafast+cabac+deblock");  // the ladder at nine 720p sessions
  EXPECT_EQ(e.rate_kbps, 2500) << "the link's cap under the policy's 4977";
  EXPECT_EQ(e.config.vbv_buffer_ms, 33) << "the config a rebuild takes has the link's VBV too";
  EXPECT_EQ(e.threads, encoder_threads(p, 1280, 720, 9));
  EXPECT_EQ(e.step, preset_step(p, 1280, 720, kStreamFps, 9));
  in.live_sessions = 8;
  EXPECT_EQ(frame_encoding(p, in).preset, "superfast");
}

TEST(FrameEncoding, Av1WhereTheCoresAffordItAndTheLinkDoesNotLimit) {
  const EncoderPolicy p = sixteen_cores();
  FrameEncodeInputs in = frame(960, 540);
  in.av1_ok = true;
  FrameEncoding e = frame_encoding(p, in);
  EXPECT_TRUE(e.av1);
  EXPECT_EQ(e.step, kPresetSteps) << "AV1 is the step above the x264 ladder";
  in.live_sessions = 5;
  EXPECT_FALSE(frame_encoding(p, in).av1) << "five 540p AV1 streams do not fit 16 cores";
  in.live_sessions = 1;
  in.link = limiting_link(1200);
  e = frame_encoding(p, in);
  EXPECT_FALSE(e.av1);
  EXPECT_LT(e.step, kPresetSteps);
  in.link = {};
  in.av1_ok = false;
  EXPECT_FALSE(frame_encoding(p, in).av1);
}

TEST(FrameEncoding, ARefineFrameLiftsOnlyACappedStream) {
  EncoderPolicy p = sixteen_cores();
  FrameEncodeInputs in = frame(640, 360);
  in.refine = true;
  EXPECT_TRUE(frame_encoding(p, in).lift_cap);  // auto's floor of 1500 kbit/s caps it
  in.refine = false;
  EXPECT_FALSE(frame_encoding(p, in).lift_cap);
  p.bitrate_kbps = 0;  // --bitrate off: crf alone, nothing to lift
  in.refine = true;
  EXPECT_EQ(frame_encoding(p, in).rate_kbps, 0);
  EXPECT_FALSE(frame_encoding(p, in).lift_cap);
}

}  // namespace

// A headset's display rate (Pose.display_hz, issue 94): 0.09 bits a pixel at its frames a second,
// the encoder's time base, and the link's share counted against it.
TEST(FrameEncoding, TheClientsDisplayRateSetsTheRateAndTheTimeBase) {
  const EncoderPolicy p = sixteen_cores();
  FrameEncodeInputs in = frame(2560, 1344);
  const FrameEncoding at60 = frame_encoding(p, in);
  in.fps = 72;
  const FrameEncoding at72 = frame_encoding(p, in);
  EXPECT_EQ(at60.config.fps, 60);
  EXPECT_EQ(at72.config.fps, 72);
  EXPECT_NEAR(at60.rate_kbps, 2560 * 1344 * 60 * 0.09 / 1000, 1.0);
  EXPECT_NEAR(at72.rate_kbps, 2560 * 1344 * 72 * 0.09 / 1000, 1.0);
  in.link.frame_rate = 36;  // half the display's frames reach the client
  EXPECT_NEAR(frame_encoding(p, in).link_ceiling_kbps, at72.rate_kbps / 2, 1.0);
}
