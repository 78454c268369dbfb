// The frame's depth grid (render_core/forward_model/depth_grid.h, the CPU core's stage) against the
// depth probe's brute-force walk over every Gaussian (cpu/pixel_depth.h), its coding
// (proto/depth_grid_coding.h), and the depth warp (tools/shown/depth_warp.h) against the
// renderer's own picture at the new pose: after a step sideways, the frame warped by its grid is
// nearer the render of where the camera is than the page's plane re-projection.
#include "shown/depth_warp.h"

#include <cmath>

#include <gtest/gtest.h>
#include <zlib.h>

#include "camera/trace.h"
#include "common/image_io.h"
#include "cpu/cpu_renderer.h"
#include "cpu/pixel_depth.h"
#include "forward_model/depth_grid.h"
#include "proto/depth_grid_coding.h"
#include "test_data.h"

namespace catgs {
namespace {

RenderOptions exact_with_grid(int cell) {
  RenderOptions o;
  o.pipeline = Pipeline::exact;
  o.depth_grid_cell = cell;
  return o;
}

TEST(DepthGrid, EachVertexIsTheProbesMedianDepthAtItsPixel) {
  CATGS_REQUIRE_DATA(scene_path, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const auto model = test::cached_scene(scene_path);
  const Camera cam = load_inria_cameras(cams, 320, 211).at(3);
  cpu::CpuRenderer renderer(model, exact_with_grid(32));
  Image img;
  renderer.render(cam, img);
  const DepthGrid& g = renderer.last_depth_grid();
  ASSERT_EQ(g.cols, 11);  // x = 0, 32, ..., 288, 320
  ASSERT_EQ(g.rows, 8);   // y = 0, 32, ..., 192, 211
  ASSERT_EQ(g.depth.size(), 88u);
  int hits = 0, agree = 0;
  for (int l = 0; l < g.rows; ++l)
    for (int k = 0; k < g.cols; ++k) {
      const int px = fm::depth_grid_pixel(k, g.cell, cam.width), py = fm::depth_grid_pixel(l, g.cell, cam.height);
      // The probe samples continuous (x, y) at forward-model pixel (x - 0.5, y - 0.5).
      const cpu::PixelDepth d = cpu::probe_pixel_depth(*model, cam, px + 0.5, py + 0.5);
      const float z = g.depth[static_cast<std::size_t>(l) * g.cols + k];
      hits += d.hit;
      // The same median where both cross 0.5 (the probe walks every Gaussian by exact depth; the
      // list by its quantised key, so a near tie may swap two neighbours).
      if (d.hit ? std::isfinite(z) && std::abs(z - d.depth) <= 0.02f * d.depth : !std::isfinite(z)) ++agree;
    }
  EXPECT_GT(hits, 80);  // a training view of the flower bed: surfaces nearly everywhere
  EXPECT_GE(agree, 85) << "of 88 vertices";
  // The vanilla pipeline has no grid.
  renderer.set_options(RenderOptions{});
  renderer.render(cam, img);
  EXPECT_EQ(renderer.last_depth_grid().cols, 0);
}

TEST(DepthGrid, CodingKeepsInverseDepthWithinHalfACode) {
  DepthGrid g;
  g.cols = 3;
  g.rows = 2;
  g.cell = 16;
  g.depth = {0.5f, 1.0f, 2.0f, INFINITY, 1000.0f, -1.0f};
  server::pb::DepthGrid m;
  server::pack_depth_grid(g, &m);
  EXPECT_FLOAT_EQ(m.inverse_depth_max(), 2.0f);  // the nearest vertex, 0.5 away
  // The codes, inflated by zlib itself.
  std::string c(6, '\0');
  uLongf size = 6;
  ASSERT_EQ(uncompress(reinterpret_cast<Bytef*>(c.data()), &size,
                       reinterpret_cast<const Bytef*>(m.inverse_depth().data()), m.inverse_depth().size()),
            Z_OK);
  ASSERT_EQ(size, 6u);
  EXPECT_EQ(static_cast<unsigned char>(c[0]), 255);
  EXPECT_EQ(static_cast<unsigned char>(c[1]), 128);  // 1/1 of 2: 127.5 rounds up
  EXPECT_EQ(static_cast<unsigned char>(c[3]), 0);    // no surface
  EXPECT_EQ(static_cast<unsigned char>(c[4]), 1);    // far but a surface: never 0
  EXPECT_EQ(static_cast<unsigned char>(c[5]), 0);    // not a depth
  const DepthGrid back = server::unpack_depth_grid(m);
  for (int i : {0, 1, 2})
    EXPECT_NEAR(1.0f / back.depth[i], 1.0f / g.depth[i],
                0.5f * 2.0f / 255.0f + 1e-6f);  // half a code, and float's rounding
  EXPECT_TRUE(std::isinf(back.depth[3]));
  // Malformed: not zlib, a stream of other codes than the shape's, the shape.
  m.set_inverse_depth("abc");
  EXPECT_THROW(server::unpack_depth_grid(m), std::invalid_argument);
  server::pb::DepthGrid other;
  DepthGrid wider = g;
  wider.cols = 4;
  wider.depth.push_back(3.0f);
  wider.depth.push_back(3.0f);
  server::pack_depth_grid(wider, &other);
  m.set_inverse_depth(other.inverse_depth());
  EXPECT_THROW(server::unpack_depth_grid(m), std::invalid_argument);
  m.set_cols(0);
  EXPECT_THROW(server::unpack_depth_grid(m), std::invalid_argument);
}

TEST(DepthWarp, AStepSidewaysIsNearerTheNewViewThanThePlanesReprojection) {
  CATGS_REQUIRE_DATA(scene_path, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const auto model = test::cached_scene(scene_path);
  const Camera a = load_inria_cameras(cams, 320, 211).at(3);
  cpu::CpuRenderer renderer(model, exact_with_grid(16));
  Image frame, want;
  renderer.render(a, frame);
  server::pb::DepthGrid sent;  // as the wire carries it
  server::pack_depth_grid(renderer.last_depth_grid(), &sent);
  const DepthGrid grid = server::unpack_depth_grid(sent);
  // The centre vertex's depth: the plane the page would choose at best.
  const float centre = grid.depth[static_cast<std::size_t>(grid.rows / 2) * grid.cols + grid.cols / 2];
  ASSERT_TRUE(std::isfinite(centre));
  const glm::vec3 right = a.orientation() * glm::vec3(1, 0, 0);
  for (const float step : {0.05f, 0.15f}) {  // of the centre's depth
    const Camera b = Camera::from_pose(a.position() + right * (step * centre), a.orientation(), a.vertical_fov_deg(),
                                       a.width, a.height);
    renderer.render(b, want);
    const shown::PagePose from = shown::page_pose_of(a), to = shown::page_pose_of(b);
    const double plane = psnr_rgba8(shown::shown_picture(frame, from, to, centre), want);
    const Image warped = shown::depth_warp_picture(frame, from, to, grid, centre);
    const double warp = psnr_rgba8(warped, want);
    std::cout << "[ info ] step " << step << " of the centre depth " << centre << ": plane " << plane
              << " dB, depth warp " << warp << " dB\n";
    EXPECT_GT(warp, plane + 1.0);
  }
  // The same pose: the frame itself.
  const Image same = shown::depth_warp_picture(frame, shown::page_pose_of(a), shown::page_pose_of(a), grid, centre);
  EXPECT_EQ(same.rgba8, frame.rgba8);
}

// A turn moves every pixel as a homography whatever its depth: the warp of a frame to a view
// turned by a fraction of a pixel to a few pixels is that view's render but for the bilinear
// samples, and those cost nothing against the supersampled ideal (issue 91: the shown picture's
// loss is the motion the warp cannot undo, not its filter). Flowers is the hard case for a filter:
// a flower bed, detail in every pixel.
TEST(DepthWarp, ATurnIsTheRenderOfTheTurnedViewAndTheFilterCostsNothing) {
  CATGS_REQUIRE_DATA(scene_path, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  const auto model = test::cached_scene(scene_path);
  const int w = 640, h = 360;
  const Camera inria = load_inria_cameras(cams, w, h).at(3);
  // The server's camera for a pose (square pixels, the principal point centred), as the warp's.
  const Camera a = Camera::from_pose(inria.position(), inria.orientation(), inria.vertical_fov_deg(), w, h);
  cpu::CpuRenderer renderer(model, exact_with_grid(32));
  Image frame;
  renderer.render(a, frame);
  const DepthGrid grid = renderer.last_depth_grid();
  for (const double px : {0.5, 3.0}) {
    const float yaw = static_cast<float>(std::atan(px / a.fx));
    const Camera b = Camera::from_pose(a.position(), a.orientation() * glm::angleAxis(yaw, glm::vec3(0, 1, 0)),
                                       a.vertical_fov_deg(), w, h);
    Image render, hi;
    renderer.render(b, render);
    renderer.render(b.rescaled(w * 4, h * 4), hi);
    const Image ideal = box_downsample(hi, 4);
    const Image warped = shown::depth_warp_picture(frame, shown::page_pose_of(a), shown::page_pose_of(b), grid, 3.0);
    const double render_db = psnr_rgba8(render, ideal), warped_db = psnr_rgba8(warped, ideal);
    std::printf("[ info ] a turn of %.1f px: the render %.2f dB, the warped frame %.2f against the ideal; %.2f apart\n",
                px, render_db, warped_db, psnr_rgba8(warped, render));
    EXPECT_GT(psnr_rgba8(warped, render), 40.0) << px << " px";
    EXPECT_GT(warped_db, render_db - 0.3) << px << " px";
  }
}

}  // namespace
}  // namespace catgs
