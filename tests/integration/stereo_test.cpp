// Issue 94: a headset's stereo pose on the real server (CPU renderer, the bundled biker). One
// frame holds both eyes side by side; each half, decoded by libavcodec, is the CPU reference's
// render of its eye (Camera::from_frustum, asymmetric frusta); and a near surface's disparity
// between the halves is what its depth (the depth probe's, independent of the renderer) says.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <vector>

#include "cpu/cpu_renderer.h"
#include "cpu/pixel_depth.h"
#include "common/image_io.h"
#include "loadgen/stream_client.h"
#include "loadgen/video_decoder.h"
#include "server_process.h"
#include "stream_checks.h"

namespace catgs::itest {
namespace {

using loadgen::HeadsetOptics;
using loadgen::StreamClient;
using loadgen::VideoDecoder;

// Columns [x0, x0 + w) of a width-wide RGBA picture of `height` rows.
Image columns_of(const std::vector<std::uint8_t>& rgba, int width, int height, int x0, int w) {
  Image out;
  out.width = w;
  out.height = height;
  out.rgba8.resize(static_cast<std::size_t>(w) * height * 4);
  for (int y = 0; y < height; ++y)
    std::copy_n(rgba.begin() + (static_cast<std::ptrdiff_t>(y) * width + x0) * 4, w * 4,
                out.rgba8.begin() + static_cast<std::ptrdiff_t>(y) * w * 4);
  return out;
}

// BT.709 luma of pixel (x, y), 0..255.
double luma(const Image& img, int x, int y) {
  const std::uint8_t* p = &img.rgba8[(static_cast<std::size_t>(y) * img.width + x) * 4];
  return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
}

constexpr int kPatch = 5;  // the matched patch is (2 kPatch + 1)^2 pixels

// Sum of squared luma differences between the patch at (x, y) of `a` and at (x - shift, y) of `b`.
double patch_ssd(const Image& a, const Image& b, int x, int y, int shift) {
  double ssd = 0;
  for (int dy = -kPatch; dy <= kPatch; ++dy)
    for (int dx = -kPatch; dx <= kPatch; ++dx) {
      const double d = luma(a, x + dx, y + dy) - luma(b, x + dx - shift, y + dy);
      ssd += d * d;
    }
  return ssd;
}

// The patch's luma standard deviation (its texture: matching needs some).
double patch_std(const Image& a, int x, int y) {
  double s = 0, s2 = 0;
  const int n = (2 * kPatch + 1) * (2 * kPatch + 1);
  for (int dy = -kPatch; dy <= kPatch; ++dy)
    for (int dx = -kPatch; dx <= kPatch; ++dx) {
      const double v = luma(a, x + dx, y + dy);
      s += v;
      s2 += v * v;
    }
  return std::sqrt(std::max(0.0, s2 / n - (s / n) * (s / n)));
}

// The shift (pixels, sub-pixel by a parabola through the best integer shift and its neighbours)
// that best matches the patch at (x, y) of `left` in `right`, searched within [lo, hi]; NaN when
// the search reaches past the image.
double measured_disparity(const Image& left, const Image& right, int x, int y, int lo, int hi) {
  if (x - hi - kPatch - 1 < 0 || x - lo + kPatch + 1 >= right.width) return std::nan("");
  int best = lo;
  double best_ssd = std::numeric_limits<double>::infinity();
  for (int s = lo; s <= hi; ++s) {
    const double ssd = patch_ssd(left, right, x, y, s);
    if (ssd < best_ssd) best_ssd = ssd, best = s;
  }
  const double a = patch_ssd(left, right, x, y, best - 1), c = patch_ssd(left, right, x, y, best + 1);
  const double curve = a - 2 * best_ssd + c;
  return best + (curve > 0 ? 0.5 * (a - c) / curve : 0.0);
}

TEST(Stereo, EachHalfIsItsEyesRenderAndDisparityMatchesDepth) {
  ServerProcess server(server_args(kBiker));
  const int EW = 192, H = 192;
  StreamClient c;
  c.connect(server.port());
  c.hello(2 * EW, H);
  VideoDecoder dec;
  const auto model = load_model(kBiker);
  cpu::CpuRenderer ref(model, RenderOptions{});
  const Trace orbit = biker_orbit(EW, H, 3);
  // Eyes a tenth of the orbit's radius apart: disparities of several pixels at this size.
  HeadsetOptics optics;
  optics.ipd = 0.1f * glm::distance(orbit[0].camera.position(), model->bounds().center());
  for (std::uint32_t i = 0; i < orbit.size(); ++i) {
    const pb::Pose pose = loadgen::stereo_pose_from_camera(orbit[i].camera, optics, i, now_ms());
    c.send_pose(pose);
    auto m = wait_for(c, 20000, [](const pb::ServerMessage& s) { return s.has_frame(); });
    ASSERT_TRUE(m) << "no frame for stereo pose " << i;
    const pb::Frame& f = m->frame();
    EXPECT_EQ(f.pose_sequence(), i);
    ASSERT_EQ(f.width(), static_cast<std::uint32_t>(2 * EW));
    ASSERT_EQ(f.eye_width(), static_cast<std::uint32_t>(EW));
    ASSERT_TRUE(f.has_left_eye() && f.has_right_eye());
    EXPECT_FLOAT_EQ(static_cast<float>(f.left_eye().position().x()),
                    static_cast<float>(pose.left_eye().position().x()));
    EXPECT_FLOAT_EQ(static_cast<float>(f.right_eye().angle_left()), static_cast<float>(pose.right_eye().angle_left()));
    EXPECT_FALSE(f.has_depth_grid());
    std::vector<std::uint8_t> rgba;
    int w = 0, h = 0;
    ASSERT_TRUE(dec.decode(f.payload(), rgba, w, h));
    ASSERT_EQ(w, 2 * EW);
    const Image left = columns_of(rgba, w, h, 0, EW), right = columns_of(rgba, w, h, EW, EW);
    const Camera lc = loadgen::eye_camera_from_pose(pose, false, EW, H);
    const Camera rc = loadgen::eye_camera_from_pose(pose, true, EW, H);
    Image want_left, want_right;
    ref.render(lc, want_left);
    ref.render(rc, want_right);
    const double pl = psnr_rgba8(left, want_left), pr = psnr_rgba8(right, want_right);
    const double swapped = psnr_rgba8(left, want_right);
    std::cout << "[ info ] stereo frame " << i << ": left " << pl << " dB, right " << pr
              << " dB, left vs the right eye " << swapped << " dB\n";
    EXPECT_GE(pl, 30.0);
    EXPECT_GE(pr, 30.0);
    EXPECT_GT(pl, swapped + 3.0) << "the left half is not the left eye's";
    if (i != 0) continue;

    // A near surface: among probed pixels where the depth is flat around (within 3% at +-3 px)
    // and the decoded picture has texture, the nearest. Its expected disparity is where the
    // probe's world point projects in the right eye (the frusta are asymmetric: the principal
    // points differ, so the disparity is not f B / z alone).
    struct Candidate {
      int x, y;
      double depth, expected;
    };
    std::vector<Candidate> found;
    for (int y = 16; y < H - 16; y += 8)
      for (int x = 24; x < EW - 16; x += 8) {
        const cpu::PixelDepth p = cpu::probe_pixel_depth(*model, lc, x + 0.5, y + 0.5);
        if (!p.hit || patch_std(left, x, y) < 12.0) continue;
        bool flat = true;
        for (auto [dx, dy] : {std::pair{-3, 0}, {3, 0}, {0, -3}, {0, 3}}) {
          const cpu::PixelDepth q = cpu::probe_pixel_depth(*model, lc, x + dx + 0.5, y + dy + 0.5);
          flat = flat && q.hit && std::fabs(q.depth - p.depth) < 0.03 * p.depth;
        }
        if (!flat) continue;
        const glm::vec3 cam = rc.R * p.point + rc.t;
        const double u = rc.fx * cam.x / cam.z + rc.cx;  // continuous image x in the right eye
        found.push_back({x, y, p.depth, (x + 0.5) - u});
      }
    ASSERT_FALSE(found.empty()) << "no flat textured surface found to match";
    std::sort(found.begin(), found.end(), [](const Candidate& a, const Candidate& b) { return a.depth < b.depth; });
    for (std::size_t k = 0; k < std::min<std::size_t>(3, found.size()); ++k) {
      const Candidate& n = found[k];
      const int centre = static_cast<int>(std::lround(n.expected));
      const double got = measured_disparity(left, right, n.x, n.y, centre - 6, centre + 6);
      std::cout << "[ info ] pixel (" << n.x << ", " << n.y << ") at depth " << n.depth << ": disparity " << got
                << " px, its depth says " << n.expected << " px\n";
      EXPECT_NEAR(got, n.expected, 1.0) << "at (" << n.x << ", " << n.y << ")";
    }
  }
}

// A stereo pose the server must refuse: one eye only, an angle past the range, left >= right.
TEST(Stereo, MalformedEyesEndOnlyThatSession) {
  ServerProcess server(server_args(kBiker));
  const Trace orbit = biker_orbit(96, 64, 1);
  StreamClient other;
  other.connect(server.port());
  other.hello(96, 64);
  auto broken = [&](auto&& edit, const std::string& words) {
    StreamClient c;
    c.connect(server.port());
    c.hello(192, 64);
    pb::Pose p = loadgen::stereo_pose_from_camera(orbit[0].camera, HeadsetOptics{}, 0, now_ms());
    edit(p);
    c.send_pose(p);
    const auto e = expect_error(c);
    ASSERT_TRUE(e) << words;
    EXPECT_EQ(e->code(), pb::ERROR_INVALID_ARGUMENT) << words;
    EXPECT_NE(e->reason().find(words), std::string::npos) << e->reason();
  };
  broken([](pb::Pose& p) { p.clear_right_eye(); }, "one eye");
  broken([](pb::Pose& p) { p.mutable_left_eye()->set_angle_up(2.0); }, "left_eye");
  broken([](pb::Pose& p) { p.mutable_right_eye()->set_angle_left(1.0); }, "angle_left < angle_right");
  broken([](pb::Pose& p) { p.mutable_right_eye()->mutable_position()->set_x(NAN); }, "right_eye");
  // The other session streams on.
  other.send_pose(loadgen::pose_from_camera(orbit[0].camera, 0, now_ms()));
  EXPECT_TRUE(wait_for(other, 20000, [](const pb::ServerMessage& s) { return s.has_frame(); }));
}

}  // namespace
}  // namespace catgs::itest
