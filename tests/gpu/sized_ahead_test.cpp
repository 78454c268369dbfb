// Frames sized ahead (CudaOptions::sized_ahead, render_core/cuda/list_plan.h): exact frames that
// give their list a capacity from the frames before them instead of reading its length back
// mid-frame, against exact frames counted first (sized_ahead off):
//  same     every frame of a real path (tumblewood x10 and flowers_sh3 on tandt_train and
//           mipnerf360_bicycle; 120 frames, 48 quick): the same render-list length and the same
//           RGBA8 image, byte for byte (the same list order: key_packing.h room_packing; the same
//           slice length, worked out on the device). Reports the frames drawn again.
//  redo     a list that outgrows its capacity (a wall of 40 huge Gaussians after frames of a wall
//           of 4): drawn again counted first, the counted renderer's image, one redo counted.
//  nowait   begin_yuv420_at of a frame sized ahead does not wait on the GPU (0 syncs before its
//           finish), and the finished planes equal the counted renderer's, code for code.
#include <cuda_runtime.h>

#include <cstdio>
#include <string>
#include <vector>

#include "gpu_test_support.h"

namespace catgs::gputest {
namespace {

catgs::cuda::CudaOptions counted_first() {
  catgs::cuda::CudaOptions o;
  o.sized_ahead = false;
  return o;
}

void same_on_path(const SharedScene& scene, const std::string& path) {
  const int W = config().W, H = config().H;
  catgs::RenderOptions o;
  o.pipeline = Pipeline::exact;
  catgs::cuda::CudaRenderer ahead(scene.dev, o), counted(scene.dev, o, counted_first());
  const auto trace = real_trace(*scene.model, trace_path(path), W, H, config().quick ? 48 : 120);
  int differing = 0, length_differs = 0, worst8 = 0;
  double worst_psnr = 1e9;
  for (const auto& tc : trace) {
    Image a, c;
    ahead.render(tc.camera, a);
    counted.render(tc.camera, c);
    const Diff d = compare(c, a);
    differing += a.rgba8 != c.rgba8;
    length_differs += ahead.last_stats().render_list_length != counted.last_stats().render_list_length;
    worst8 = std::max(worst8, d.max_abs8);
    worst_psnr = std::min(worst_psnr, d.psnr);
  }
  const auto diag = ahead.diagnostics();
  char note[200];
  std::snprintf(note, sizeof note, "%zu frames: %zu sized ahead, %zu drawn again; images differing %d, lengths %d",
                trace.size(), diag.sized_ahead_frames, diag.sized_ahead_redos, differing, length_differs);
  add({"sized", scene.model->name, path, "exact", worst_psnr, 0, worst8, -1, -1,
       differing == 0 && length_differs == 0 && diag.sized_ahead_frames + 1 >= trace.size(), note});
}

class SizedAhead : public GpuTest {};

TEST_F(SizedAhead, SameAsCountedOnRealPaths) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2", "flowers_sh3"}, {"tandt_train", "mipnerf360_bicycle"});
  for (const SharedScene* s : {&tumblewood(), &flowers()})
    for (const char* path : {"tandt_train", "mipnerf360_bicycle"}) same_on_path(*s, path);
}

TEST_F(SizedAhead, ALongerListIsDrawnAgain) {
  const Camera cam = front_camera(640, 360);
  const auto few = catgs::cuda::DeviceScene::upload(*wall_scene(4), 0);
  const auto many = catgs::cuda::DeviceScene::upload(*wall_scene(40), 0);
  catgs::RenderOptions o;
  o.pipeline = Pipeline::exact;
  catgs::cuda::CudaRenderer ahead(few, o), counted(many, o, counted_first());
  Image a, c;
  for (int i = 0; i < 3; ++i) ahead.render(cam, a);  // counted, then sized ahead at 4 walls' length
  const std::size_t short_list = ahead.last_stats().render_list_length;
  const auto before = ahead.diagnostics();
  ahead.set_scene(many);  // ten times the list: past the capacity
  ahead.render(cam, a);
  counted.render(cam, c);
  const auto after = ahead.diagnostics();
  const Diff d = compare(c, a);
  char note[200];
  std::snprintf(note, sizeof note, "list %zu -> %zu (counted %zu); sized ahead %zu -> %zu, drawn again %zu -> %zu",
                short_list, ahead.last_stats().render_list_length, counted.last_stats().render_list_length,
                before.sized_ahead_frames, after.sized_ahead_frames, before.sized_ahead_redos, after.sized_ahead_redos);
  add({"sized", "wall", "4->40", "exact", d.psnr, d.max_abs, d.max_abs8,
       static_cast<long long>(counted.last_stats().render_list_length),
       static_cast<long long>(ahead.last_stats().render_list_length),
       a.rgba8 == c.rgba8 && before.sized_ahead_frames == 2 && before.sized_ahead_redos == 0 &&
           after.sized_ahead_frames == 3 && after.sized_ahead_redos == 1 &&
           ahead.last_stats().render_list_length == counted.last_stats().render_list_length &&
           ahead.last_stats().render_list_length > 5 * short_list,
       note});
}

TEST_F(SizedAhead, BeginDoesNotWait) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"}, {"tandt_train"});
  const int w = 1278, h = 718;  // not a multiple of the tile size
  catgs::RenderOptions o;
  o.pipeline = Pipeline::exact;
  const SharedScene& scene = tumblewood();
  catgs::cuda::CudaRenderer ahead(scene.dev, o), counted(scene.dev, o, counted_first());
  const auto trace = real_trace(*scene.model, trace_path("tandt_train"), w, h, 12);
  std::vector<std::uint8_t> ya(w * h), ua(w * h / 4), va(w * h / 4), yc(w * h), uc(w * h / 4), vc(w * h / 4);
  const catgs::Yuv420Target ta{w, h, catgs::MemoryKind::host, ya.data(), w, ua.data(), w / 2, va.data(), w / 2},
      tc{w, h, catgs::MemoryKind::host, yc.data(), w, uc.data(), w / 2, vc.data(), w / 2};
  int waited = 0, differing = 0;
  for (std::size_t i = 0; i < trace.size(); ++i) {
    ahead.begin_yuv420_at(trace[i].camera, 0.0, ta);
    if (i > 0) waited += ahead.diagnostics().syncs_last_frame;  // the first frame is counted first
    ahead.finish_yuv420();
    counted.render_yuv420_at(trace[i].camera, 0.0, tc);
    differing += ya != yc || ua != uc || va != vc;
  }
  char note[160];
  std::snprintf(note, sizeof note, "%zu frames %dx%d: syncs before finish %d, frames with differing planes %d",
                trace.size(), w, h, waited, differing);
  add({"sized", scene.model->name, "tandt", "exact", 0, 0, 0, -1, -1, waited == 0 && differing == 0, note});
}

}  // namespace
}  // namespace catgs::gputest
