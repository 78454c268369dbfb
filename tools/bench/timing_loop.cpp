#include "bench/timing_loop.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>

#include "cpu/cpu_renderer.h"

#if CATGS_HAVE_CUDA
#include <cuda_runtime.h>

#include "cuda/cuda_renderer.h"
#endif
#include "common/image_io.h"

namespace catgs::bench {

namespace {

// The server's render-list budget is lifted: a benchmark measures the lists a variant makes, and
// wide speculation windows list several times the default budget on purpose.
RenderOptions options_of(const Variant& variant, const TimingPlan& plan) {
  RenderOptions o;
  o.lod_error_px = plan.lod_error_px;
  o.pipeline = variant.pipeline;
  o.speculation = variant.speculation;
  o.occlusion_culling = variant.occlusion_culling;
  o.list_budget = RenderListBudget::unlimited();
  return o;
}

PipelineResult result_of(const Variant& variant) {
  PipelineResult res;
  res.name = variant.name;
  res.pipeline = variant.pipeline;
  return res;
}

// DIR/FILE_NAME.png, creating DIR; a scene with LOD adds the bound (FILE_NAME_lodPX.png).
void write_snapshot(const Image& image, const std::string& dir, const std::string& file_name, const TimingPlan& plan) {
  std::filesystem::create_directories(dir);
  char lod[32] = "";
  if (plan.lod) std::snprintf(lod, sizeof lod, "_lod%g", plan.lod_error_px);
  write_png(image, dir + "/" + file_name + lod + ".png");
}

// A key frame: the group it closes (by that group's W), and the group it opens.
void record_key_frame(PipelineResult& res, double ms, const FrameStats& s) {
  res.window.push_back(s.window);
  if (s.subframe_rejected) res.rejected_ms.push_back(ms);
  if (s.window == 0) res.full_ms.push_back(ms);
  if (res.open_window > 0) {  // the key frame closes the open group
    auto& group = res.groups[res.open_window];
    ++group.count;
    group.served += res.open_served;
    group.rejected += s.subframe_rejected ? 1 : 0;
  }
  res.open_window = s.window;
  res.open_served = 0;
}

void record_lod_quality(PipelineResult& res, double psnr) {
  if (std::isinf(psnr))
    ++res.lod_identical;
  else
    res.lod_psnr.push_back(psnr);
}

// --aa-reference: `frame` and `full` (full detail, same pose) against `hi` (full detail at
// aa_factor times the size), box-filtered down.
void record_aa_quality(PipelineResult& res, const Image& frame, const Image& full, const Image& hi, int aa_factor) {
  const Image aa = box_downsample(hi, aa_factor);
  res.lod_psnr_aa.push_back(psnr_rgba8(frame, aa));
  res.full_psnr_aa.push_back(psnr_rgba8(full, aa));
}

// The reference's camera: the same view at aa_factor times the size.
Camera aa_camera(const Camera& c, int aa_factor) { return c.rescaled(c.width * aa_factor, c.height * aa_factor); }

PipelineResult time_cpu_variant(const std::shared_ptr<const GaussianModel>& model, const Variant& variant,
                                const TimingPlan& plan, const std::shared_ptr<const GaussianModel>& reference_model) {
  auto r = make_renderer("cpu", model, options_of(variant, plan));
  if (auto* core = dynamic_cast<cpu::CpuRenderer*>(r.get())) core->count_changes(plan.count_changes);
  PipelineResult res = result_of(variant);
  Image img, full, hi;
  // LOD against full detail (after timing): the exact pipeline at lod_error_px 0.
  RenderOptions full_detail;
  full_detail.lod_error_px = 0.0f;
  full_detail.list_budget = RenderListBudget::unlimited();
  const auto reference =
      plan.lod && plan.quality_every > 0 ? make_renderer("cpu", reference_model, full_detail) : nullptr;
  for (int k = 0; k < plan.warmup; ++k) r->render_at(plan.camera_at(k), plan.time_at(k), img);
  for (int k = 0; k < plan.frames; ++k) {
    const int frame = plan.warmup + k;
    const auto t0 = std::chrono::steady_clock::now();
    r->render_at(plan.camera_at(frame), plan.time_at(frame), img);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    record_frame(res, ms, r->last_stats());
    if (reference && k % plan.quality_every == 0) {
      reference->render(plan.camera_at(frame), full);
      record_lod_quality(res, psnr_rgba8(img, full));
      if (plan.aa_factor >= 2) {
        reference->render(aa_camera(plan.camera_at(frame), plan.aa_factor), hi);
        record_aa_quality(res, img, full, hi, plan.aa_factor);
      }
    }
  }
  if (!plan.snapshot_dir.empty()) {
    write_snapshot(img, plan.snapshot_dir, model->name + "_cpu_" + res.name, plan);
    // The last compared pose's references, to look at beside the frame: full detail, the large
    // render (to box-filter with another tool) and its box filter.
    if (!hi.rgba8.empty()) {
      const std::string base = plan.snapshot_dir + "/" + model->name + "_cpu_";
      write_png(full, base + "full_detail.png");
      write_png(hi, base + "full_detail_x" + std::to_string(plan.aa_factor) + ".png");
      write_png(box_downsample(hi, plan.aa_factor), base + "aa_reference.png");
    }
  }
  return res;
}

}  // namespace

void record_frame(PipelineResult& res, double ms, const FrameStats& s) {
  res.frame_ms.push_back(ms);
  res.pre.push_back(s.preprocess_ms);
  res.keys.push_back(s.keys_ms);
  res.sort.push_back(s.sort_ms);
  res.ranges.push_back(s.ranges_ms);
  res.raster.push_back(s.rasterize_ms);
  res.list.push_back(static_cast<double>(s.render_list_length));
  res.visible.push_back(static_cast<double>(s.visible));
  res.chunks.push_back(static_cast<double>(s.chunks_preprocessed));
  res.behind_opaque.push_back(static_cast<double>(s.entries_behind_opaque));
  res.changing_entries.push_back(static_cast<double>(s.entries_changing_pixels));
  res.changing_gaussians.push_back(static_cast<double>(s.gaussians_changing_pixels));
  res.preprocessed.push_back(static_cast<double>(s.gaussians_preprocessed));
  res.hidden_chunks.push_back(static_cast<double>(s.gaussians_in_hidden_chunks));
  res.hidden_groups.push_back(static_cast<double>(s.gaussians_in_hidden_groups));
  res.hidden_alone.push_back(static_cast<double>(s.gaussians_hidden_alone));
  res.entries_hidden_px.push_back(static_cast<double>(s.entries_hidden_pixels));
  (s.key_frame ? res.key_ms : res.sub_ms).push_back(ms);
  if (s.key_frame)
    record_key_frame(res, ms, s);
  else
    ++res.open_served;
  const double stage[6] = {s.preprocess_ms, s.keys_ms, s.sort_ms, s.ranges_ms, s.rasterize_ms, s.merge_ms};
  for (int k = 0; k < 6; ++k) (s.key_frame ? res.key_stage : res.sub_stage)[k].push_back(stage[k]);
}

std::vector<PipelineResult> time_on_cpu(const std::shared_ptr<const GaussianModel>& model,
                                        const std::vector<Variant>& variants, const TimingPlan& plan,
                                        const std::shared_ptr<const GaussianModel>& reference) {
  std::vector<PipelineResult> results;
  for (const Variant& variant : variants)
    results.push_back(time_cpu_variant(model, variant, plan, reference ? reference : model));
  return results;
}

#if CATGS_HAVE_CUDA
namespace {

void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess)
    throw std::runtime_error(std::string(what) + ": " + cudaGetErrorName(e) + ": " + cudaGetErrorString(e));
}

// Two CUDA events around the work queued on a stream between start() and stop().
class EventTimer {
 public:
  EventTimer() {
    check(cudaEventCreate(&start_), "cudaEventCreate");
    check(cudaEventCreate(&end_), "cudaEventCreate");
  }
  ~EventTimer() {
    cudaEventDestroy(start_);
    cudaEventDestroy(end_);
  }
  EventTimer(const EventTimer&) = delete;
  EventTimer& operator=(const EventTimer&) = delete;

  void start(cudaStream_t stream) { check(cudaEventRecord(start_, stream), "cudaEventRecord"); }
  // Waits for the end event; milliseconds since start().
  float stop(cudaStream_t stream) {
    check(cudaEventRecord(end_, stream), "cudaEventRecord");
    check(cudaEventSynchronize(end_), "cudaEventSynchronize");
    float ms = 0;
    check(cudaEventElapsedTime(&ms, start_, end_), "cudaEventElapsedTime");
    return ms;
  }

 private:
  cudaEvent_t start_ = nullptr, end_ = nullptr;
};

RenderOptions exact_options() {
  RenderOptions o;
  o.pipeline = Pipeline::exact;
  o.lod_error_px = 0.0f;  // full detail
  o.list_budget = RenderListBudget::unlimited();
  return o;
}

// --quality-every: a timed catgs frame against a full exact render of the same pose by a second
// renderer. A sub-frame gives the image quality (PSNR over 8-bit RGB, max abs error of the float
// image), a key frame the render-list growth (catgs key list / exact list). With LOD, every
// compared frame also gives its PSNR against the full-detail render (lod_psnr).
class QualityCheck {
 public:
  QualityCheck(const std::shared_ptr<const cuda::DeviceScene>& scene, int aa_factor)
      : reference_(scene, exact_options()), aa_factor_(aa_factor) {
    if (aa_factor_ >= 2) aa_reference_ = std::make_unique<cuda::CudaRenderer>(scene, exact_options());
  }

  void compare(PipelineResult& res, const FrameStats& stats, const cuda::DeviceFrame& frame, const Camera& camera,
               bool lod) {
    reference_.render(camera, full_);
    if (lod) {
      download(frame);
      record_lod_quality(res, psnr_rgba8(image_, full_));
      if (aa_reference_) {  // a renderer of its own: its buffers stay at the large size
        aa_reference_->render(aa_camera(camera, aa_factor_), hi_);
        record_aa_quality(res, image_, full_, hi_, aa_factor_);
      }
    }
    if (res.pipeline != Pipeline::catgs) return;
    if (stats.key_frame) {
      res.list_growth.push_back(static_cast<double>(stats.render_list_length) /
                                std::max<double>(1.0, static_cast<double>(reference_.last_stats().render_list_length)));
      return;
    }
    download(frame);
    const double p = psnr_rgba8(image_, full_);
    double max_abs = 0.0;
    for (std::size_t i = 0; i < image_.rgb.size(); ++i)
      max_abs = std::max(max_abs, static_cast<double>(std::fabs(image_.rgb[i] - full_.rgb[i])));
    if (std::isinf(p))
      ++res.subframes_inf;
    else
      res.sub_psnr.push_back(p);
    res.sub_max_abs.push_back(max_abs);
  }

  // The references of `camera` beside a snapshot (as the CPU path writes them): full detail, and
  // with --aa-reference its box-filtered large render. Written once per run (the first variant's).
  void write_references(const Camera& camera, const std::string& base) {
    if (references_written_) return;
    references_written_ = true;
    reference_.render(camera, full_);
    write_png(full_, base + "full_detail.png");
    if (!aa_reference_) return;
    aa_reference_->render(aa_camera(camera, aa_factor_), hi_);
    write_png(box_downsample(hi_, aa_factor_), base + "aa_reference.png");
  }

 private:
  void download(const cuda::DeviceFrame& frame) {
    const std::size_t pixels = static_cast<std::size_t>(frame.width) * frame.height;
    image_.width = frame.width;
    image_.height = frame.height;
    image_.rgb.resize(pixels * 3);
    image_.rgba8.resize(pixels * 4);
    check(cudaMemcpy(image_.rgb.data(), frame.rgb, pixels * 3 * sizeof(float), cudaMemcpyDeviceToHost), "cudaMemcpy");
    check(cudaMemcpy(image_.rgba8.data(), frame.rgba8, pixels * 4, cudaMemcpyDeviceToHost), "cudaMemcpy");
  }

  cuda::CudaRenderer reference_;
  int aa_factor_;
  std::unique_ptr<cuda::CudaRenderer> aa_reference_;  // --aa-reference
  Image image_, full_, hi_;
  bool references_written_ = false;
};

PipelineResult time_cuda_variant(const std::shared_ptr<const cuda::DeviceScene>& scene, const Variant& variant,
                                 const TimingPlan& plan, QualityCheck& quality, std::size_t used_before_scene) {
  cuda::CudaRenderer r(scene, options_of(variant, plan));
  PipelineResult res = result_of(variant);
  EventTimer timer;
  for (int k = 0; k < plan.warmup; ++k) {
    r.render_device_at(plan.camera_at(k), plan.time_at(k));
    (void)r.last_stats();
  }
  const bool compare = (variant.pipeline == Pipeline::catgs || plan.lod) && plan.quality_every > 0;
  const std::size_t allocs_before = r.diagnostics().allocations;
  for (int k = 0; k < plan.frames; ++k) {
    const Camera cam = plan.camera_at(plan.warmup + k);
    timer.start(r.stream());
    const cuda::DeviceFrame frame = r.render_device_at(cam, plan.time_at(plan.warmup + k));
    const float ms = timer.stop(r.stream());
    const FrameStats stats = r.last_stats();
    record_frame(res, ms, stats);
    res.heaviest.push_back(static_cast<double>(r.diagnostics().heaviest_tile_entries));             // after timing
    if (compare && k % plan.quality_every == 0) quality.compare(res, stats, frame, cam, plan.lod);  // after timing too
  }
  const cuda::CudaRenderer::Diagnostics d = r.diagnostics();
  res.allocations_timed = d.allocations - allocs_before;
  res.peak_buffer_bytes = d.peak_buffer_bytes;
  res.device_used_bytes = cuda::device_memory_used() - used_before_scene;
  res.syncs = d.syncs_last_frame;
  if (!plan.snapshot_dir.empty()) {
    Image img;
    r.render(plan.camera_at(plan.warmup + plan.frames / 2), img);
    write_snapshot(img, plan.snapshot_dir, scene->name() + "_" + res.name, plan);
    if (plan.lod)
      quality.write_references(plan.camera_at(plan.warmup + plan.frames / 2),
                               plan.snapshot_dir + "/" + scene->name() + "_");
  }
  return res;
}

}  // namespace

std::vector<PipelineResult> time_on_cuda(const std::shared_ptr<const cuda::DeviceScene>& scene,
                                         const std::vector<Variant>& variants, const TimingPlan& plan,
                                         std::size_t used_before_scene,
                                         const std::shared_ptr<const cuda::DeviceScene>& reference) {
  QualityCheck quality(reference ? reference : scene, plan.lod ? plan.aa_factor : 0);
  std::vector<PipelineResult> results;
  for (const Variant& variant : variants)
    results.push_back(time_cuda_variant(scene, variant, plan, quality, used_before_scene));
  return results;
}
#endif

}  // namespace catgs::bench
