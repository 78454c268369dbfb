// Message validation: poses whose numbers would overflow in the server's own maths, and the
// server's --max-viewport limit (issue 22, findings 5 and 7).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "session/message_validation.h"

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

TEST(MessageValidation, ShownLatencyIsFiniteAndBounded) {
  CameraPose out;
  pb::Pose p = pose_with_orientation(1, 0, 0, 0);
  for (double ok : {0.0, 16.7, 3.6e6}) {
    p.set_shown_latency_ms(ok);
    EXPECT_FALSE(check_pose(p, out).has_value()) << ok;
  }
  for (double bad : {-1.0, 3.6e6 + 1, std::nan(""), std::numeric_limits<double>::infinity()}) {
    p.set_shown_latency_ms(bad);
    const auto v = check_pose(p, out);
    ASSERT_TRUE(v.has_value()) << bad;
    EXPECT_EQ(v->code, pb::ERROR_INVALID_ARGUMENT);
  }
}

}  // namespace
