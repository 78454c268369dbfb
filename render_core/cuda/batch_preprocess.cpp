// CudaRenderer::preprocess_batch (and the Renderer interface's preprocess_together over it):
// stage 1 of several renderers' next frames in one pass over their scene (issue 47: the sessions
// on one scene share the reading of its Gaussians).
#include <stdexcept>
#include <string>

#include "renderer_state.h"

namespace catgs::cuda {

namespace {

[[noreturn]] void refuse(const std::string& why) { throw std::invalid_argument("preprocess_batch: " + why); }

}  // namespace

bool CudaRenderer::take_batched(const Camera& camera) {
  State& s = *state_;
  if (!s.batched) return false;
  s.batched = false;
  return same_camera(camera, s.batched_camera);
}

void CudaRenderer::preprocess_batch(const std::vector<CudaRenderer*>& renderers, const std::vector<Camera>& cameras) {
  const std::size_t views = renderers.size();
  if (views == 0 || views > static_cast<std::size_t>(stages::kMaxBatchViews))
    refuse(std::to_string(views) + " renderers (1 to " + std::to_string(stages::kMaxBatchViews) + ")");
  if (cameras.size() != views)
    refuse(std::to_string(views) + " renderers but " + std::to_string(cameras.size()) + " cameras");
  for (std::size_t k = 0; k < views; ++k) {
    const CudaRenderer* r = renderers[k];
    if (!r) refuse("renderer " + std::to_string(k) + " is null");
    for (std::size_t j = 0; j < k; ++j)
      if (renderers[j] == r) refuse("renderer " + std::to_string(k) + " is also renderer " + std::to_string(j));
    if (r->scene_ != renderers[0]->scene_) refuse("renderer " + std::to_string(k) + " draws another scene");
    if (r->options_.pipeline == Pipeline::catgs) refuse("catgs renderers pre-process their key frames their own way");
    if (r->options_.pipeline != renderers[0]->options_.pipeline) refuse("exact and vanilla renderers in one batch");
    if (r->options_.lod_error_px != renderers[0]->options_.lod_error_px) refuse("renderers at different LOD bounds");
    validate_camera(cameras[k]);
  }
  CudaRenderer& lead = *renderers[0];
  const DeviceGuard on(lead.scene_->device());
  const DeviceScene& scene = *lead.scene_;
  const uint64_t n = scene.size();
  const uint64_t chunks = fm::chunk_count(n);
  State& batch = *lead.state_;
  if (!batch.host_batch_views) {
    CATGS_CUDA(cudaMallocHost(&batch.host_batch_views, stages::kMaxBatchViews * sizeof(stages::BatchView)));
    CATGS_CUDA(cudaEventCreateWithFlags(&batch.batch_copied, cudaEventDisableTiming));
  } else {
    CATGS_CUDA(cudaEventSynchronize(batch.batch_copied));  // the last batch's views have left the staging
  }
  batch.batch_views.ensure(stages::kMaxBatchViews * sizeof(stages::BatchView), "batch views", &batch.allocations);
  batch.batch_chunks.ensure(std::max<uint64_t>(1, chunks) * sizeof(uint32_t), "batch chunks", &batch.allocations);
  batch.batch_mask.ensure(std::max<uint64_t>(1, chunks) * sizeof(uint32_t), "batch view masks", &batch.allocations);
  batch.batch_count.ensure(sizeof(unsigned), "batch chunk count", &batch.allocations);

  // Each view: its buffers at its size, its counters zeroed and kStart on its own stream; the
  // batch's stream waits for every renderer's queued work (its previous frame still reads them).
  for (std::size_t k = 0; k < views; ++k) {
    State& s = *renderers[k]->state_;
    if (!s.batch_join) CATGS_CUDA(cudaEventCreateWithFlags(&s.batch_join, cudaEventDisableTiming));
    const stages::CameraParams cam = camera_params(cameras[k]);
    s.ensure_frame_buffers(n, static_cast<uint32_t>(cam.tiles_x * cam.tiles_y),
                           static_cast<std::size_t>(cameras[k].width) * cameras[k].height);
    s.note_peak();
    auto* counters = s.counters.as<unsigned long long>();
    CATGS_CUDA(cudaMemsetAsync(counters, 0, kCounterSlots * sizeof(unsigned long long), s.stream));
    CATGS_CUDA(cudaEventRecord(s.events[kStart], s.stream));
    if (k > 0) {
      CATGS_CUDA(cudaEventRecord(s.batch_join, s.stream));
      CATGS_CUDA(cudaStreamWaitEvent(batch.stream, s.batch_join, 0));
    }
    batch.host_batch_views[k] = {
        cam,         s.projected(), s.live_chunk_list(), counters + kVisibleCount, counters + kReadDepthLowComplement,
        s.big_list()};
  }
  auto* views_device = batch.batch_views.as<stages::BatchView>();
  CATGS_CUDA(cudaMemcpyAsync(views_device, batch.host_batch_views, views * sizeof(stages::BatchView),
                             cudaMemcpyHostToDevice, batch.stream));
  CATGS_CUDA(cudaEventRecord(batch.batch_copied, batch.stream));
  CATGS_CUDA(cudaMemsetAsync(batch.batch_count.as<void>(), 0, sizeof(unsigned), batch.stream));
  const stages::BatchChunks either{
      {batch.batch_chunks.as<uint32_t>(), batch.batch_count.as<unsigned>(), nullptr, nullptr, 0, nullptr, 0},
      batch.batch_mask.as<uint32_t>()};
  stages::preprocess_batch(scene_view(scene, lead.options_.lod_error_px), lead.options_.pipeline != Pipeline::vanilla,
                           batch.host_batch_views, views_device, static_cast<int>(views), either, batch.stream);
  CATGS_CUDA(cudaEventRecord(batch.batch_join, batch.stream));
  // Every view's stream continues from the batch's end; its frame then starts at the counts.
  for (std::size_t k = 0; k < views; ++k) {
    State& s = *renderers[k]->state_;
    if (k > 0) CATGS_CUDA(cudaStreamWaitEvent(s.stream, batch.batch_join, 0));
    CATGS_CUDA(cudaEventRecord(s.events[kPreprocessed], s.stream));
    s.batched = true;
    s.batched_camera = cameras[k];
    s.batched_views = static_cast<int>(views);
  }
}

bool CudaRenderer::shares_stage1_with(const Renderer& other) const {
  const auto* o = dynamic_cast<const CudaRenderer*>(&other);
  return o && o->scene_ == scene_ && options_.pipeline != Pipeline::catgs &&
         o->options_.pipeline == options_.pipeline && o->options_.lod_error_px == options_.lod_error_px;
}

void CudaRenderer::preprocess_together(const std::vector<Renderer*>& renderers, const std::vector<Camera>& cameras) {
  std::vector<CudaRenderer*> views;
  for (std::size_t k = 0; k < renderers.size(); ++k) {
    auto* r = dynamic_cast<CudaRenderer*>(renderers[k]);
    if (!r)
      throw std::invalid_argument("preprocess_together: renderer " + std::to_string(k) + " is not a CUDA renderer");
    views.push_back(r);
  }
  if (views.empty() || views[0] != this)
    throw std::invalid_argument("preprocess_together: the batch's first renderer must be the one asked");
  preprocess_batch(views, cameras);
}

}  // namespace catgs::cuda
