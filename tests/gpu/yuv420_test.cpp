// The server's frame path (issue 5):
//  yuv420  CudaRenderer::render_yuv420_at (GPU colour conversion) into a pitched host target and
//          into device planes: every Y, Cb, Cr code value equals the CPU reference conversion
//          (rgba_to_yuv420_bt709) of the same frame's RGBA8, for exact and catgs frames, at a size
//          that is not a multiple of the tile size (biker, 24 frames of tandt_train; 4 quick).
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

#include "colour/yuv420.h"
#include "gpu_test_support.h"

namespace catgs::gputest {
namespace {

// Code values of `got` that differ from `want` (same size), and the largest difference.
struct PlaneDiff {
  long long mismatched = 0;
  int max_diff = 0;
};
void diff_plane(const std::uint8_t* got, int got_stride, const std::vector<std::uint8_t>& want, int w, int h,
                PlaneDiff& d) {
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      const int e = std::abs(int(got[static_cast<std::size_t>(r) * got_stride + c]) -
                             int(want[static_cast<std::size_t>(r) * w + c]));
      d.mismatched += e != 0;
      d.max_diff = std::max(d.max_diff, e);
    }
}

// render_yuv420_at on the GPU vs the CPU conversion of the same frame, host and device targets
// (every third frame through begin_yuv420_at / finish_yuv420 with another frame drawn between).
// `reference` renders the same frames as `converted` (same options, same cameras and times).
void yuv420_check(const std::string& name, const std::string& view, catgs::cuda::CudaRenderer& reference,
                  catgs::cuda::CudaRenderer& converted, const std::vector<Camera>& cams) {
  PlaneDiff host, device;
  int w = cams[0].width, h = cams[0].height;
  const int pad = 64;  // pitched host target: strides past the row
  std::vector<std::uint8_t> y((w + pad) * h), u((w / 2 + pad) * h / 2), v((w / 2 + pad) * h / 2);
  std::uint8_t* dev = nullptr;
  std::size_t pitch = 0;
  if (cudaMallocPitch(reinterpret_cast<void**>(&dev), &pitch, w, h * 2) != cudaSuccess)
    throw std::runtime_error("cudaMallocPitch failed");
  std::vector<std::uint8_t> dev_host(pitch * h * 2);
  double convert_ms = 0;
  int not_ready = 0;  // begun frames frame_ready() never called done
  for (std::size_t i = 0; i < cams.size(); ++i) {
    const double t = static_cast<double>(i) / 120.0;
    const bool to_device = i % 2 == 1;  // alternate the two targets over the frames
    catgs::Yuv420Target target{w,        h,          catgs::MemoryKind::host, y.data(), w + pad, u.data(), w / 2 + pad,
                               v.data(), w / 2 + pad};
    if (to_device)  // Y rows, then Cb rows, then Cr rows, all at the allocation's pitch
      target = {w,
                h,
                catgs::MemoryKind::device,
                dev,
                int(pitch),
                dev + pitch * h,
                int(pitch),
                dev + pitch * h + pitch * h / 2,
                int(pitch)};
    // Every third frame in halves, as a render lane with frames in flight draws it: begun, another
    // renderer's frame drawn meanwhile (the lane's next session), then finished.
    const bool in_halves = i % 3 == 2;
    if (in_halves) converted.begin_yuv420_at(cams[i], t, target);
    Image img;
    reference.render_at(cams[i], t, img);
    const catgs::Yuv420Image want = catgs::rgba_to_yuv420_bt709(img.rgba8.data(), w, h, w * 4);
    if (in_halves) {  // the lane's question (Renderer::frame_ready) turns true without a finish
      const auto asked = std::chrono::steady_clock::now();
      while (!converted.frame_ready() && std::chrono::steady_clock::now() - asked < std::chrono::seconds(10)) {}
      if (!converted.frame_ready()) ++not_ready;
    }
    convert_ms += in_halves ? converted.finish_yuv420() : converted.render_yuv420_at(cams[i], t, target);
    PlaneDiff& d = to_device ? device : host;
    if (to_device) {
      cudaMemcpy(dev_host.data(), dev, dev_host.size(), cudaMemcpyDeviceToHost);
      diff_plane(dev_host.data(), int(pitch), want.y, w, h, d);
      diff_plane(dev_host.data() + pitch * h, int(pitch), want.u, w / 2, h / 2, d);
      diff_plane(dev_host.data() + pitch * h + pitch * h / 2, int(pitch), want.v, w / 2, h / 2, d);
    } else {
      diff_plane(y.data(), w + pad, want.y, w, h, d);
      diff_plane(u.data(), w / 2 + pad, want.u, w / 2, h / 2, d);
      diff_plane(v.data(), w / 2 + pad, want.v, w / 2, h / 2, d);
    }
  }
  cudaFree(dev);
  char note[200];
  std::snprintf(note, sizeof note,
                "%zu frames %dx%d; code values differing: host %lld, device %lld; conversion %.3f ms/frame; "
                "never ready %d",
                cams.size(), w, h, host.mismatched, device.mismatched, convert_ms / static_cast<double>(cams.size()),
                not_ready);
  add({"yuv420", name, view, catgs::pipeline_name(converted.options().pipeline), 0, 0,
       std::max(host.max_diff, device.max_diff), -1, -1,
       host.mismatched == 0 && device.mismatched == 0 && not_ready == 0, note});
}

// The server's frame path: GPU colour conversion == CPU reference, for `pl`'s frames.
void yuv420_checks(Pipeline pl) {
  const int w = 1918, h = 1078;  // 1080p-like, not a multiple of 16 or 32
  std::vector<Camera> path;
  for (const auto& tc : real_trace(*biker().model, trace_path("tandt_train"), w, h, config().quick ? 4 : 24))
    path.push_back(tc.camera);
  catgs::RenderOptions o;
  o.pipeline = pl;
  catgs::cuda::CudaRenderer reference(biker().dev, o), converted(biker().dev, o);
  yuv420_check("sc.biker", "tandt", reference, converted, path);
}

class Yuv420 : public GpuTest {};

TEST_F(Yuv420, Exact) {
  CATGS_GPU_REQUIRE({"biker"}, {"tandt_train"});
  yuv420_checks(Pipeline::exact);
}

TEST_F(Yuv420, Catgs) {
  CATGS_GPU_REQUIRE({"biker"}, {"tandt_train"});
  yuv420_checks(Pipeline::catgs);
}

}  // namespace
}  // namespace catgs::gputest
