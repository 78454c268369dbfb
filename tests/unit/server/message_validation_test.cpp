// Message validation: poses whose numbers would overflow in the server's own maths, and the
// server's --max-viewport limit (issue 22, findings 5 and 7).
#include <gtest/gtest.h>

#include <cmath>
#include <initializer_list>
#include <limits>

#include "proto/message_validation.h"

namespace {

using namespace catgs::server;

pb::Pose pose_with_orientation(double w, double x, double y, double z) {
  pb::Pose p;
  p.mutable_position()->set_x(1.0);
  p.mutable_position()->set_y(2.0);
  p.mutable_position()->set_z(3.0);
  p.mutable_orientation()->set_w(w);
  p.mutable_orientation()->set_x(x);
  p.mutable_orientation()->set_y(y);
  p.mutable_orientation()->set_z(z);
  p.set_vertical_fov_deg(60.0);
  return p;
}

// Finding 7: (1e200, 0, 0, 0) squared overflows to Inf, the quaternion normalised to zero and the
// session ended in ERROR_INTERNAL; validation must refuse it as the client's error.
TEST(MessageValidation, HugeQuaternionIsInvalidArgument) {
  for (const double big : {1e200, -1e200, 1e155, 1e31}) {
    SCOPED_TRACE(big);
    CameraPose out;
    const auto bad = check_pose(pose_with_orientation(big, 0, 0, 0), out);
    ASSERT_TRUE(bad.has_value());
    EXPECT_EQ(bad->code, pb::ERROR_INVALID_ARGUMENT);
    EXPECT_NE(bad->reason.find("orientation"), std::string::npos) << bad->reason;
    EXPECT_TRUE(check_pose(pose_with_orientation(0, 0, big, 0), out).has_value());
  }
}

TEST(MessageValidation, LargeButRepresentableQuaternionIsNormalised) {
  CameraPose out;
  ASSERT_FALSE(check_pose(pose_with_orientation(3e29, 0, 4e29, 0), out).has_value());
  EXPECT_NEAR(out.orientation.w, 0.6f, 1e-6f);
  EXPECT_NEAR(out.orientation.y, 0.8f, 1e-6f);
  EXPECT_TRUE(check_pose(pose_with_orientation(0, 0, 0, 0), out).has_value());
}

// Finding 5: the viewport a client may ask for is bounded by --max-viewport (pixels and longer
// side, either orientation), on top of the protocol's 16..4096 per side.
TEST(MessageValidation, ViewportWithinServerLimit) {
  const ViewportLimit uhd;  // default 3840x2160
  Viewport v;
  EXPECT_FALSE(check_viewport(3840, 2160, uhd, v).has_value());
  EXPECT_EQ(v.width, 3840);
  EXPECT_FALSE(check_viewport(2160, 3840, uhd, v).has_value()) << "portrait of the same size";
  EXPECT_FALSE(check_viewport(1281, 721, uhd, v).has_value());
  EXPECT_EQ(v.width, 1280) << "odd sizes round down to even";
  for (const auto& [w, h] :
       {std::pair{4096u, 4096u}, std::pair{3842u, 2160u}, std::pair{3000u, 3000u}, std::pair{4096u, 16u}}) {
    SCOPED_TRACE(std::to_string(w) + "x" + std::to_string(h));
    const auto bad = check_viewport(w, h, uhd, v);
    ASSERT_TRUE(bad.has_value());
    EXPECT_EQ(bad->code, pb::ERROR_INVALID_ARGUMENT);
    EXPECT_NE(bad->reason.find("--max-viewport 3840x2160"), std::string::npos) << bad->reason;
  }
  const ViewportLimit hd{1280, 720};
  EXPECT_FALSE(check_viewport(720, 1280, hd, v).has_value());
  EXPECT_TRUE(check_viewport(1282, 720, hd, v).has_value());
  EXPECT_TRUE(check_viewport(8, 64, hd, v).has_value()) << "the protocol's minimum still holds";
}

TEST(MessageValidation, HelloUsesTheLimit) {
  pb::Hello hello;
  hello.set_protocol_version(1);
  hello.set_viewport_width(1920);
  hello.set_viewport_height(1080);
  Viewport v;
  EXPECT_FALSE(check_hello(hello, ViewportLimit{}, v).has_value());
  const auto bad = check_hello(hello, ViewportLimit{1280, 720}, v);
  ASSERT_TRUE(bad.has_value());
  EXPECT_EQ(bad->code, pb::ERROR_INVALID_ARGUMENT);
}

TEST(MessageValidation, QualityBitrateRange) {
  pb::Quality q;
  for (std::uint32_t ok : {0u, 100u, 5000u, 100000u}) {
    q.set_max_bitrate_kbps(ok);
    EXPECT_FALSE(check_quality(q).has_value()) << ok;
  }
  for (std::uint32_t bad : {1u, 99u, 100001u, 4000000000u}) {
    q.set_max_bitrate_kbps(bad);
    const auto v = check_quality(q);
    ASSERT_TRUE(v.has_value()) << bad;
    EXPECT_EQ(v->code, pb::ERROR_INVALID_ARGUMENT);
    EXPECT_NE(v->reason.find(std::to_string(bad)), std::string::npos) << v->reason;
  }
}

// A Pose's time field: the values in `ok` pass, those in `bad` are INVALID_ARGUMENT.
void expect_pose_time_bounds(void (pb::Pose::*set)(double), std::initializer_list<double> ok,
                             std::initializer_list<double> bad) {
  CameraPose out;
  pb::Pose p = pose_with_orientation(1, 0, 0, 0);
  for (double v : ok) {
    (p.*set)(v);
    EXPECT_FALSE(check_pose(p, out).has_value()) << v;
  }
  for (double v : bad) {
    (p.*set)(v);
    const auto violation = check_pose(p, out);
    ASSERT_TRUE(violation.has_value()) << v;
    EXPECT_EQ(violation->code, pb::ERROR_INVALID_ARGUMENT);
  }
}

TEST(MessageValidation, ShownLatencyIsFiniteAndBounded) {
  expect_pose_time_bounds(&pb::Pose::set_shown_latency_ms, {0.0, 16.7, 3.6e6},
                          {-1.0, 3.6e6 + 1, std::nan(""), std::numeric_limits<double>::infinity()});
}

TEST(MessageValidation, FrameReceiptTimeIsFiniteAndBounded) {
  expect_pose_time_bounds(&pb::Pose::set_received_ms, {0.0, 12345.678, 1e15},
                          {-0.5, 1e15 * 1.01, std::nan(""), -std::numeric_limits<double>::infinity()});
}

// A headset's display rate (issue 94): 0 (unknown) or 24..240 Hz.
TEST(MessageValidation, DisplayRateIsZeroOrAHeadsetsRate) {
  expect_pose_time_bounds(&pb::Pose::set_display_hz, {0.0, 24.0, 72.0, 90.0, 240.0},
                          {-72.0, 10.0, 23.9, 240.5, std::nan(""), std::numeric_limits<double>::infinity()});
}

// ---- ExportVideoRequest (issue 38: "Export video" from the page) ----

// A path of `poses` poses `dt` s apart, moving along x and looking down +z.
pb::ExportVideoRequest export_request(int poses, float dt = 0.5f, std::uint32_t w = 160, std::uint32_t h = 90,
                                      std::uint32_t fps = 10) {
  pb::ExportVideoRequest r;
  r.set_export_id(7);
  r.set_width(w);
  r.set_height(h);
  r.set_fps(fps);
  for (int k = 0; k < poses; ++k)
    for (float v : {k * dt, 0.1f * k, 0.0f, -3.0f, 1.0f, 0.0f, 0.0f, 0.0f, 50.0f}) r.add_path(v);
  return r;
}

std::string export_refusal(const pb::ExportVideoRequest& r, const ExportLimits& limits = {}) {
  ExportPlan plan;
  const auto bad = check_export_request(r, limits, plan);
  if (!bad) return "";
  EXPECT_EQ(bad->code, pb::ERROR_INVALID_ARGUMENT);
  EXPECT_TRUE(plan.frames.empty()) << "a refused request filled the plan";
  return bad->reason;
}

TEST(ExportValidation, AGoodPathIsSampledAtTheVideoRate) {
  ExportPlan plan;
  // 4 poses 0.5 s apart from t = 100 s: 1.5 s of path, 16 frames at 10 fps (t = 0 .. 1.5 s).
  pb::ExportVideoRequest r = export_request(4);
  for (int k = 0; k < 4; ++k) r.set_path(k * kExportFloatsPerPose, 100.0f + 0.5f * k);
  r.set_pipeline("catgs");
  ASSERT_FALSE(check_export_request(r, {}, plan).has_value());
  EXPECT_EQ(plan.export_id, 7u);
  EXPECT_EQ(plan.width, 160);
  EXPECT_EQ(plan.height, 90);
  EXPECT_EQ(plan.pipeline, catgs::Pipeline::catgs);
  ASSERT_EQ(plan.frames.size(), 16u);
  EXPECT_NEAR(plan.duration_s, 1.6, 1e-9);
  EXPECT_NEAR(plan.frames[5].time_s, 0.5, 1e-6);
  EXPECT_EQ(plan.frames[5].camera.width, 160);
  // Frame 5 is pose 1 (x = 0.1); frame 2 is 40% of the way from pose 0 to pose 1.
  EXPECT_NEAR(plan.frames[5].camera.position().x, 0.1f, 1e-5f);
  EXPECT_NEAR(plan.frames[2].camera.position().x, 0.04f, 1e-5f);
  r.clear_pipeline();
  ASSERT_FALSE(check_export_request(r, {}, plan).has_value());
  EXPECT_EQ(plan.pipeline, catgs::Pipeline::exact) << "the default is full quality";
}

TEST(ExportValidation, CapsNameTheirFlags) {
  // A million poses: refused by count, before any pose is looked at.
  EXPECT_NE(export_refusal(export_request(1000000))
                .find("a path of 1000000 poses is over the server's "
                      "--export-max-poses 1800"),
            std::string::npos);
  EXPECT_NE(export_refusal(export_request(4, 0.5f, 7680, 4320)).find("7680x4320 outside 16..4096"), std::string::npos);
  EXPECT_NE(export_refusal(export_request(4, 0.5f, 4096, 2304)).find("over the server's --export-max-size 3840x2160"),
            std::string::npos);
  EXPECT_EQ(export_refusal(export_request(4, 0.5f, 2160, 3840)), "") << "portrait 4K fits as --max-viewport does";
  EXPECT_NE(export_refusal(export_request(4, 0.5f, 160, 90, 120)).find("fps 120 outside 1..--export-max-fps 60"),
            std::string::npos);
  EXPECT_NE(export_refusal(export_request(4, 0.5f, 160, 90, 0)).find("fps 0"), std::string::npos);
  // 11 minutes of path (two poses 660 s apart).
  EXPECT_NE(export_refusal(export_request(2, 660.0f)).find("over the server's --export-max-seconds 600"),
            std::string::npos);
  ExportLimits tight;
  tight.max_poses = 3;
  tight.max_fps = 5;
  tight.max_seconds = 1;
  tight.max_width = 64;
  tight.max_height = 64;
  EXPECT_NE(export_refusal(export_request(4), tight).find("--export-max-poses 3"), std::string::npos);
  EXPECT_NE(export_refusal(export_request(3, 0.25f, 96, 64, 5), tight).find("--export-max-size 64x64"),
            std::string::npos);
  EXPECT_EQ(export_refusal(export_request(3, 0.25f, 64, 64, 5), tight), "");
  EXPECT_NE(export_refusal(export_request(3, 0.75f, 64, 64, 5), tight).find("--export-max-seconds 1"),
            std::string::npos);
}

TEST(ExportValidation, BadPathsAreRefused) {
  EXPECT_NE(export_refusal(export_request(1)).find("at least 2 poses"), std::string::npos);
  pb::ExportVideoRequest r = export_request(3);
  r.add_path(1.0f);
  EXPECT_NE(export_refusal(r).find("28 floats, not 9 a pose"), std::string::npos);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  struct Case {
    int field;  // of pose 1
    float value;
    const char* says;
  };
  for (const Case c : {Case{0, nan, "pose 1: time is NaN or Inf"}, Case{1, inf, "pose 1: Pose has NaN or Inf"},
                       Case{6, nan, "pose 1: Pose has NaN or Inf"}, Case{8, 0.5f, "pose 1: vertical_fov_deg"},
                       Case{0, -1.0f, "pose 1: time goes backwards"}}) {
    r = export_request(3);
    r.set_path(kExportFloatsPerPose + c.field, c.value);
    EXPECT_NE(export_refusal(r).find(c.says), std::string::npos) << c.says << " / " << export_refusal(r);
  }
  r = export_request(3);
  for (int i = 4; i < 8; ++i) r.set_path(kExportFloatsPerPose + i, 0.0f);
  EXPECT_NE(export_refusal(r).find("pose 1: Pose orientation is a zero quaternion"), std::string::npos);
  r = export_request(3, 0.5f, 161, 90);
  EXPECT_NE(export_refusal(r).find("must be even"), std::string::npos);
  r = export_request(3);
  r.set_pipeline("warp");
  EXPECT_NE(export_refusal(r).find("unknown pipeline 'warp'"), std::string::npos);
}

}  // namespace
