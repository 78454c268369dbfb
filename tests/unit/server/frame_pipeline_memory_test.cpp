// A frame whose device buffers cannot grow (issue 61; session/frame_pipeline.h): the render job
// reports it as out of memory, with the renderer's buffer bytes, rather than as a failure that
// ends the session; halve_list_budget() then halves the renderer's list budget (down to
// kMinListBytes) so its later frames are drawn in passes. A renderer that throws CUDA's own
// error, as the CUDA core does, stands in for a GPU that ran out of memory.
#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "base/cuda_error.h"
#include "process/server_metrics.h"
#include "session/frame_pipeline.h"
#include "session/session_settings.h"

namespace {

using namespace catgs;
using namespace catgs::server;

// Throws CudaError `code` from every render, or, `at_finish`, from the frame's finish (a frame
// begun on a lane, whose failure shows when its planes are waited for); its buffers hold 123 MiB.
class FailingRenderer : public Renderer {
 public:
  explicit FailingRenderer(int code, bool at_finish = false) : code_(code), at_finish_(at_finish) {}
  std::string name() const override { return "cuda"; }
  void render(const Camera&, Image&) override { fail(); }
  void begin_yuv420_at(const Camera& camera, double time_s, const Yuv420Target& out) override {
    if (!at_finish_) return Renderer::begin_yuv420_at(camera, time_s, out);
    begin_frame();
  }
  double finish_yuv420() override {
    if (!at_finish_) return Renderer::finish_yuv420();
    end_frame();
    fail();
  }
  [[noreturn]] void fail() const {
    throw cuda::CudaError("CUDA renderer: render-list keys buffer of 95073784 bytes: cudaMalloc failed: out of memory",
                          code_);
  }
  const FrameStats& last_stats() const override { return stats_; }
  const RenderOptions& options() const override { return options_; }
  void set_options(const RenderOptions& o) override { options_ = o; }
  std::uint64_t device_buffer_bytes() const override { return 123ull << 20; }

 private:
  int code_;
  bool at_finish_;
  FrameStats stats_;
  RenderOptions options_;
};

// A pipeline over a one-Gaussian model and `renderer` (pipelined, CUDA device 0).
struct TestPipeline {
  FrameSettings settings;
  ServerMetrics metrics;
  FramePipeline frames{settings, metrics};
  explicit TestPipeline(std::unique_ptr<Renderer> renderer) {
    auto model = std::make_shared<GaussianModel>();
    model->resize(1);
    frames.open(std::move(renderer), model, 0, true, false);
  }
};

FramePipeline::Rendered render_once(FramePipeline& frames) {
  FramePipeline::PendingPose pose;
  pose.pose.position = {0.0f, 0.0f, -3.0f};  // the identity orientation looks down +z at the origin
  frames.offer(pose);
  FramePipeline::JobShape shape;
  shape.width = 64;
  shape.height = 64;
  FramePipeline::StartedRender started = frames.start_render(shape);
  FramePipeline::Rendered r = frames.begin_render(std::move(started.job), std::move(started.planes), false);
  frames.finish_render(r);
  frames.end_render();
  return r;
}

// The same when the frame was begun and its finish fails (render_scheduler.h "Frames in flight").
TEST(FramePipelineMemory, OutOfMemoryAtTheFinishIsReported) {
  TestPipeline p(std::make_unique<FailingRenderer>(2, /*at_finish=*/true));
  FramePipeline::Rendered oom = render_once(p.frames);
  EXPECT_TRUE(oom.out_of_memory);
  EXPECT_FALSE(oom.render_begun);
  EXPECT_NE(oom.error.find("out of memory"), std::string::npos) << oom.error;
  EXPECT_EQ(oom.buffer_bytes, 123ull << 20);
}

TEST(FramePipelineMemory, OutOfMemoryIsReportedAndHalvesTheListBudget) {
  auto renderer = std::make_unique<FailingRenderer>(2);  // cudaErrorMemoryAllocation
  FailingRenderer* r = renderer.get();
  RenderOptions o;
  o.list_budget.max_bytes = 512ull << 20;
  r->set_options(o);
  TestPipeline p(std::move(renderer));
  FramePipeline& frames = p.frames;
  FramePipeline::Rendered oom = render_once(frames);
  EXPECT_TRUE(oom.out_of_memory);
  EXPECT_FALSE(oom.over_budget);
  EXPECT_NE(oom.error.find("out of memory"), std::string::npos) << oom.error;
  EXPECT_EQ(oom.buffer_bytes, 123ull << 20);
  const FramePipeline::JobResult failed = frames.take_failed(std::move(oom));
  EXPECT_TRUE(failed.out_of_memory);
  EXPECT_EQ(failed.buffer_bytes, 123ull << 20);

  EXPECT_EQ(frames.halve_list_budget(), 256ull << 20);
  EXPECT_EQ(r->options().list_budget.max_bytes, 256ull << 20);
  for (int k = 0; k < 8; ++k) frames.halve_list_budget();
  EXPECT_EQ(r->options().list_budget.max_bytes, FramePipeline::kMinListBytes) << "halved below its floor";
}

TEST(FramePipelineMemory, AnotherCudaErrorIsAFailure) {
  TestPipeline p(std::make_unique<FailingRenderer>(700));  // cudaErrorIllegalAddress
  const FramePipeline::Rendered r = render_once(p.frames);
  EXPECT_FALSE(r.out_of_memory);
  EXPECT_FALSE(r.error.empty());
}

}  // namespace
