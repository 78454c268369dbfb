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

// Throws CudaError `code` from its first `fail_times` renders (-1: every one), or, `at_finish`,
// from the frame's finish (a frame begun on a lane, whose failure shows when its planes are
// waited for); its buffers hold 123 MiB and a list of 2 M entries.
class FailingRenderer : public Renderer {
 public:
  explicit FailingRenderer(int code, bool at_finish = false, int fail_times = -1)
      : code_(code), at_finish_(at_finish), fail_times_(fail_times) {}
  std::string name() const override { return "cuda"; }
  void render(const Camera& camera, Image& out) override {  // then a black frame
    ++renders;
    if (fail_times_ < 0 || renders <= fail_times_) fail();
    out.width = camera.width;
    out.height = camera.height;
    out.rgb.assign(static_cast<std::size_t>(camera.width) * camera.height * 3, 0.0f);
    out.rgba8.assign(static_cast<std::size_t>(camera.width) * camera.height * 4, 0);
  }
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
  BufferShape buffer_shape() const override { return {1000, 2'000'000}; }
  int renders = 0;

 private:
  int code_;
  bool at_finish_;
  int fail_times_;
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
  EXPECT_TRUE(oom.record.out_of_memory);
  EXPECT_FALSE(oom.render_begun);
  EXPECT_NE(oom.record.error.find("out of memory"), std::string::npos) << oom.record.error;
  EXPECT_EQ(oom.record.buffer_bytes, 123ull << 20);
}

// A buffer that cannot grow, frame after frame: the frame is tried again kMemoryFallbacks times
// (in passes within the list buffers held, then coarser), then reported as out of memory, with
// the renderer's buffer bytes; halve_list_budget() halves the budget down to kMinListBytes.
TEST(FramePipelineMemory, OutOfMemoryIsReportedAfterTheFallbacksAndHalvesTheListBudget) {
  auto renderer = std::make_unique<FailingRenderer>(2);  // cudaErrorMemoryAllocation
  FailingRenderer* r = renderer.get();
  RenderOptions o;
  o.list_budget.max_bytes = 512ull << 20;
  r->set_options(o);
  TestPipeline p(std::move(renderer));
  FramePipeline& frames = p.frames;
  FramePipeline::Rendered oom = render_once(frames);
  EXPECT_EQ(r->renders, 1 + FramePipeline::kMemoryFallbacks);
  EXPECT_TRUE(oom.record.out_of_memory);
  EXPECT_FALSE(oom.record.over_budget);
  EXPECT_NE(oom.record.error.find("out of memory"), std::string::npos) << oom.record.error;
  EXPECT_EQ(oom.record.buffer_bytes, 123ull << 20);
  EXPECT_EQ(oom.record.buffer_shape.list_entries, 2'000'000u);
  const FramePipeline::JobResult failed = frames.take_failed(std::move(oom));
  EXPECT_TRUE(failed.record.out_of_memory);
  EXPECT_EQ(failed.record.buffer_bytes, 123ull << 20);
  EXPECT_EQ(p.metrics.render_memory_fallbacks_total.load(), 0u) << "a frame lost after every fallback was not drawn";

  // The fallback's budget: the 2 M entries the list buffers hold, 24 bytes an entry.
  EXPECT_EQ(r->options().list_budget.max_bytes, 48'000'000u);
  EXPECT_EQ(frames.halve_list_budget(),
            24'000'000u < FramePipeline::kMinListBytes ? FramePipeline::kMinListBytes : 24'000'000u);
  for (int k = 0; k < 8; ++k) frames.halve_list_budget();
  EXPECT_EQ(r->options().list_budget.max_bytes, FramePipeline::kMinListBytes) << "halved below its floor";
  // As many more passes as the budget is smaller: what the server's budget drew, it draws still.
  EXPECT_EQ(r->options().list_budget.max_passes, 16u * 16u);
}

// A buffer that cannot grow once: the frame is drawn again in the same job, in passes within the
// list buffers held, and counts as a frame (issue 73: no frame dropped); Stats and /metrics say so.
TEST(FramePipelineMemory, AFrameWhoseBufferCannotGrowIsDrawnInPasses) {
  auto renderer = std::make_unique<FailingRenderer>(2, false, /*fail_times=*/1);
  FailingRenderer* r = renderer.get();
  TestPipeline p(std::move(renderer));
  FramePipeline::Rendered drawn = render_once(p.frames);
  EXPECT_EQ(r->renders, 2);
  EXPECT_TRUE(drawn.record.error.empty()) << drawn.record.error;
  EXPECT_FALSE(drawn.record.out_of_memory);
  EXPECT_EQ(drawn.record.memory_fallback, 1);
  EXPECT_NE(drawn.record.memory_note.find("render-list keys"), std::string::npos) << drawn.record.memory_note;
  EXPECT_EQ(r->options().list_budget.max_bytes, 48'000'000u);
  EXPECT_GT(r->options().list_budget.max_passes, RenderListBudget{}.max_passes);
  EXPECT_EQ(p.metrics.render_memory_fallbacks_total.load(), 1u);
  EXPECT_NE(p.metrics.prometheus_text().find("catgs_render_memory_fallbacks_total 1"), std::string::npos);
}

// A frame lost after every fallback: its pose waits again (a still camera sends no other pose),
// unless a newer one already waits.
TEST(FramePipelineMemory, ALostFramesPoseWaitsAgain) {
  TestPipeline p(std::make_unique<FailingRenderer>(2));
  FramePipeline::Rendered lost = render_once(p.frames);
  ASSERT_TRUE(lost.record.out_of_memory);
  ASSERT_FALSE(p.frames.pending().has_value());
  EXPECT_TRUE(p.frames.retry_lost());
  ASSERT_TRUE(p.frames.pending().has_value());
  EXPECT_EQ(p.frames.pending()->sequence, lost.job.pose.sequence);
  FramePipeline::PendingPose newer = *p.frames.pending();
  newer.sequence += 5;
  p.frames.offer(newer);
  EXPECT_TRUE(p.frames.retry_lost());
  EXPECT_EQ(p.frames.pending()->sequence, newer.sequence) << "a newer pose is not replaced by the lost one";
}

TEST(FramePipelineMemory, AnotherCudaErrorIsAFailure) {
  TestPipeline p(std::make_unique<FailingRenderer>(700));  // cudaErrorIllegalAddress
  const FramePipeline::Rendered r = render_once(p.frames);
  EXPECT_FALSE(r.record.out_of_memory);
  EXPECT_FALSE(r.record.error.empty());
}

}  // namespace
