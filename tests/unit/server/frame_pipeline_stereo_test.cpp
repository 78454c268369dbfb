// A headset's frame (issue 94; session/frame_pipeline.h begin_views): the render job draws the
// left eye into the left half of the frame's I420 planes and the right eye into the right half.
// Each half, before any encode, is compared with the CPU reference's own render of that eye alone
// (a fresh renderer, Camera::from_frustum at an eye's size): bit for bit where the eyes share
// nothing; where the right eye reads the left eye's occlusion map (the server's default), above 50
// dB against that eye drawn in full, a difference no codec's picture would show.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <iostream>
#include <memory>

#include "camera/trace.h"
#include "cpu/cpu_renderer.h"
#include "loadgen/stream_client.h"
#include "process/server_metrics.h"
#include "session/frame_pipeline.h"
#include "session/session_settings.h"
#include "test_data.h"

namespace {

using namespace catgs;
using namespace catgs::server;

constexpr int kEyeWidth = 96, kHeight = 80;

// A head looking at the biker from the orbit's start, eyes `ipd` apart (the asymmetric frusta of
// catgs-loadgen's HeadsetOptics).
pb::Pose headset_pose(const GaussianModel& model, float ipd) {
  const Bounds b = model.bounds();
  GeneratorParams p;
  p.width = kEyeWidth;
  p.height = kHeight;
  p.rate_hz = 10.0;
  p.duration_s = 0.1;
  const float r = 1.4f * glm::length(b.extent());
  const Trace orbit = make_orbit(b, r, 0.2f * r, 120.0f, p);
  loadgen::HeadsetOptics optics;
  optics.ipd = ipd;
  return loadgen::stereo_pose_from_camera(orbit[0].camera, optics, 0, 0.0);
}

// The stereo frame's planes, rendered by a pipeline over `model` with `options`.
Yuv420Image stereo_planes(const std::shared_ptr<const GaussianModel>& model, const RenderOptions& options,
                          const pb::Pose& pose) {
  FrameSettings settings;
  ServerMetrics metrics;
  FramePipeline frames{settings, metrics};
  frames.open(std::make_unique<cpu::CpuRenderer>(model, options), model, -1, true, false);
  FramePipeline::PendingPose pending;
  EXPECT_FALSE(check_pose(pose, pending.pose).has_value());
  EXPECT_FALSE(check_stereo(pose, pending.eyes).has_value());
  pending.sent = pending.pose;
  frames.offer(pending);
  FramePipeline::JobShape shape;
  shape.width = 2 * kEyeWidth;
  shape.height = kHeight;
  FramePipeline::StartedRender started = frames.start_render(shape);
  FramePipeline::Rendered r = frames.begin_render(std::move(started.job), std::move(started.planes), false);
  frames.finish_render(r);
  EXPECT_EQ(r.record.error, "");
  return std::move(*r.planes);
}

// One eye rendered alone by a fresh CPU renderer.
Yuv420Image eye_alone(const std::shared_ptr<const GaussianModel>& model, const RenderOptions& options,
                      const pb::Pose& pose, bool right) {
  cpu::CpuRenderer ref(model, options);
  Yuv420Image out;
  ref.render_yuv420_at(loadgen::eye_camera_from_pose(pose, right, kEyeWidth, kHeight), 0.0,
                       out.target(kEyeWidth, kHeight));
  return out;
}

// Columns [x0, x0 + w) of plane `p` (stride `stride`, `rows` rows) against plane `q` (w wide):
// the differing samples and the squared error's sum.
struct PlaneDiff {
  std::size_t differing = 0;
  double squared = 0;
  std::size_t samples = 0;
};
void add_diff(PlaneDiff& d, const std::vector<std::uint8_t>& p, int stride, int x0, const std::vector<std::uint8_t>& q,
              int w, int rows) {
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < w; ++x) {
      const int a = p[static_cast<std::size_t>(y) * stride + x0 + x], b = q[static_cast<std::size_t>(y) * w + x];
      d.differing += a != b;
      d.squared += static_cast<double>((a - b) * (a - b));
      d.samples++;
    }
}

PlaneDiff half_against(const Yuv420Image& frame, const Yuv420Image& eye, bool right) {
  PlaneDiff d;
  const int x0 = right ? kEyeWidth : 0;
  add_diff(d, frame.y, frame.width, x0, eye.y, kEyeWidth, kHeight);
  add_diff(d, frame.u, frame.width / 2, x0 / 2, eye.u, kEyeWidth / 2, kHeight / 2);
  add_diff(d, frame.v, frame.width / 2, x0 / 2, eye.v, kEyeWidth / 2, kHeight / 2);
  return d;
}

double psnr(const PlaneDiff& d) {
  return d.squared == 0 ? INFINITY : 10.0 * std::log10(255.0 * 255.0 * d.samples / d.squared);
}

TEST(FramePipelineStereo, EachHalfIsItsEyeAloneBitForBit) {
  const auto model = test::cached_scene(test::bundled_scene());
  const pb::Pose pose = headset_pose(*model, 0.3f);
  RenderOptions options;  // exact, no occlusion culling: the eyes share nothing
  const Yuv420Image frame = stereo_planes(model, options, pose);
  ASSERT_EQ(frame.width, 2 * kEyeWidth);
  for (bool right : {false, true}) {
    const Yuv420Image eye = eye_alone(model, options, pose, right);
    const PlaneDiff d = half_against(frame, eye, right);
    EXPECT_EQ(d.differing, 0u) << (right ? "right" : "left") << " eye";
    // And not the other eye's picture: the halves differ.
    const PlaneDiff other = half_against(frame, eye_alone(model, options, pose, !right), right);
    EXPECT_LT(psnr(other), 40.0) << "the halves are not swapped";
  }
}

TEST(FramePipelineStereo, WithOcclusionCullingTheRightEyeReadsTheLeftsMapAndStaysAbove50dB) {
  const auto model = test::cached_scene(test::bundled_scene());
  const pb::Pose pose = headset_pose(*model, 0.3f);
  RenderOptions culled;
  culled.occlusion_culling = true;  // as the server runs (--occlusion-cull)
  const Yuv420Image frame = stereo_planes(model, culled, pose);
  // The reference: each eye drawn alone and in full (no map to read).
  const RenderOptions full;
  const PlaneDiff left = half_against(frame, eye_alone(model, full, pose, false), false);
  const PlaneDiff right = half_against(frame, eye_alone(model, full, pose, true), true);
  EXPECT_EQ(left.differing, 0u) << "the left eye reads no map (the pipeline's first frame)";
  std::cout << "[ info ] right eye with the left eye's occlusion map: " << right.differing << " of " << right.samples
            << " samples differ, " << psnr(right) << " dB\n";
  EXPECT_GT(psnr(right), 50.0);
}

}  // namespace
