// The frame pipeline (frame_pipeline.h): the pose slots and host buffers on the strand, the
// render and encode stages in their jobs, the encoder configured by the encoder policy
// (encode/encoder_policy.h).
#include "base/thread_clock.h"
#include "session/frame_pipeline.h"

#include <algorithm>
#include <iostream>
#include <iterator>

#include "base/allocation_faults.h"
#include "base/cuda_error.h"
#include "camera/camera.h"
#include "proto/depth_grid_coding.h"
#include "encode/encoder_policy.h"
#include "encode/frame_encoding.h"
#include "render/render_scheduler.h"

namespace catgs::server {

namespace {

// cudaErrorMemoryAllocation (driver_types.h), without the CUDA headers: a device buffer that
// could not grow.
constexpr int kCudaOutOfMemory = 2;

// A frame rendering on a GPU, counted in ServerMetrics' in-flight renders until it ends (also when
// the render throws).
class GpuRenderCount {
 public:
  GpuRenderCount(ServerMetrics& metrics, int gpu)
      : metrics_(metrics), gpu_(gpu), begin_(gpu >= 0 ? metrics.gpu_render_begin(gpu) : 1) {}
  ~GpuRenderCount() {
    if (gpu_ >= 0 && !ended_) metrics_.gpu_render_end(gpu_);
  }
  // The frames that rendered with this one, itself included: the mean of the counts at its start and end.
  double end() {
    const int end = gpu_ >= 0 ? metrics_.gpu_render_end(gpu_) : 1;
    ended_ = true;
    return 0.5 * (begin_ + end);
  }

 private:
  ServerMetrics& metrics_;
  int gpu_, begin_;
  bool ended_ = false;
};

// The columns [x0, x0 + width) of a target (x0 and width even): an eye's half of a stereo frame.
Yuv420Target columns_of(const Yuv420Target& t, int x0, int width) {
  Yuv420Target half = t;
  half.width = width;
  half.y += x0;
  half.u += x0 / 2;
  half.v += x0 / 2;
  return half;
}

// A stereo frame's record from its eyes' (issue 94): the work of both (Gaussians, entries, stage
// times), a key frame only where both were.
FrameStats both_eyes(const FrameStats& left, const FrameStats& right) {
  FrameStats s = right;
  s.visible += left.visible;
  s.chunks_preprocessed += left.chunks_preprocessed;
  s.entries_behind_opaque += left.entries_behind_opaque;
  s.render_list_length += left.render_list_length;
  s.longest_pass = std::max(s.longest_pass, left.longest_pass);
  s.passes += left.passes;
  s.preprocess_ms += left.preprocess_ms;
  s.keys_ms += left.keys_ms;
  s.sort_ms += left.sort_ms;
  s.ranges_ms += left.ranges_ms;
  s.rasterize_ms += left.rasterize_ms;
  s.merge_ms += left.merge_ms;
  s.total_ms += left.total_ms;
  s.key_frame = left.key_frame && right.key_frame;
  s.subframe_rejected = left.subframe_rejected || right.subframe_rejected;
  return s;
}

void set_pose(const glm::vec3& position, const glm::quat& orientation, pb::Vec3* p, pb::Quat* q) {
  p->set_x(position.x);
  p->set_y(position.y);
  p->set_z(position.z);
  q->set_w(orientation.w);
  q->set_x(orientation.x);
  q->set_y(orientation.y);
  q->set_z(orientation.z);
}

void set_eye(const EyePose& e, pb::EyeView* out) {
  set_pose(e.position, e.orientation, out->mutable_position(), out->mutable_orientation());
  out->set_angle_left(e.angle_left);
  out->set_angle_right(e.angle_right);
  out->set_angle_up(e.angle_up);
  out->set_angle_down(e.angle_down);
}

}  // namespace

void FramePipeline::open(std::unique_ptr<Renderer> renderer, std::shared_ptr<const GaussianModel> model, int gpu,
                         bool pipelined, bool av1_ok, std::shared_ptr<ContentRates> content_rates) {
  // One-job path: a GPU frame goes to NVENC as a CUDA frame (no host copy); x264 ignores it.
  const bool device_input = !pipelined && renderer && renderer->name() == "cuda";
  encoder_.open(av1_ok, std::move(content_rates), gpu, device_input, model ? model->name : std::string());
  renderer_ = std::move(renderer);
  if (renderer_) server_list_budget_ = renderer_->options().list_budget;
  model_ = std::move(model);
  if (model_ && !model_->lod.empty()) cut_counter_ = std::make_unique<CutCounter>(*model_);
  gpu_ = gpu;
  pipelined_ = pipelined;
  for (int i = 0; pipelined_ && i < 2; ++i) free_planes_.push_back(std::make_unique<Yuv420Image>());
}

bool FramePipeline::drop_pending() {
  const bool had = pending_.has_value();
  pending_.reset();
  return had;
}

void FramePipeline::refine(Clock::time_point now) {
  pending_ = last_started_;
  pending_->refine = true;
  pending_->received = now;
  // A still camera is where the client said, not where its motion led: the refine frame draws the
  // client's pose (a predicted one overshoots the stop).
  pending_->pose = pending_->sent;
  pending_->predicted = false;
}

bool FramePipeline::can_start_render() const {
  if (rendering_ || rendered_ || !pending_) return false;
  return !pipelined_ || !free_planes_.empty();  // both buffers busy (one rendering is excluded above)
}

Camera FramePipeline::camera_of(const Job& job) {
  if (job.pose.eyes) return eye_cameras(job)[0];
  return Camera::from_pose(job.pose.pose.position, job.pose.pose.orientation, job.pose.pose.vertical_fov_deg,
                           job.shape.width, job.shape.height);
}

std::array<Camera, 2> FramePipeline::eye_cameras(const Job& job) {
  const int w = job.shape.width / 2, h = job.shape.height;
  auto camera = [w, h](const EyePose& e) {
    return Camera::from_frustum(e.position, e.orientation, e.angle_left, e.angle_right, e.angle_up, e.angle_down, w, h);
  };
  return {camera(job.pose.eyes->left), camera(job.pose.eyes->right)};
}

FramePipeline::StartedRender FramePipeline::start_render(const JobShape& shape) {
  StartedRender s;
  if (pipelined_) {
    s.planes = std::move(free_planes_.back());
    free_planes_.pop_back();
  }
  // Pipelined, the number is given at the encode (start_encode): a frame skipped before its
  // encode must leave no gap, as Frame sequences rise by one from 0.
  s.job = Job{*pending_, shape, force_idr_, pipelined_ ? 0 : next_frame_sequence_++};
  s.job.posted_at = Clock::now();
  // No render of this session runs now (rendering_ is false): the renderer's options may change.
  // A failure here is left to the lane, where the job reports it.
  try {
    s.job.lod_error_px = set_lod_bound(camera_of(s.job));
  } catch (const std::exception&) {
    s.job.lod_error_px = -1.0f;
  }
  last_started_ = pending_;
  last_started_->refine = false;
  pending_.reset();
  force_idr_ = false;
  rendering_ = true;
  return s;
}

std::uint64_t FramePipeline::halve_list_budget() {
  return limit_list_budget(renderer_->options().list_budget.max_bytes / 2);
}

std::uint64_t FramePipeline::limit_list_budget(std::uint64_t max_bytes) {
  RenderOptions o = renderer_->options();
  RenderListBudget& b = o.list_budget;
  b.max_bytes = std::max(max_bytes, kMinListBytes);
  // As many more passes as the budget is smaller than the server's: a view the server's budget
  // draws is drawn still (in more, shorter passes), never refused as over the budget.
  const std::uint64_t full = server_list_budget_.max_bytes;
  const std::uint64_t times = full > b.max_bytes ? (full + b.max_bytes - 1) / b.max_bytes : 1;
  b.max_passes = std::min<std::uint64_t>(server_list_budget_.max_passes * times, 4096);
  renderer_->set_options(o);
  frames_since_fallback_ = 0;
  return b.max_bytes;
}

bool FramePipeline::out_of_memory_in_flight() {
  try {
    throw;
  } catch (const OutOfMemoryError&) {
    return true;
  } catch (const cuda::CudaError& e) {
    return e.code() == kCudaOutOfMemory;
  } catch (...) {
    return false;
  }
}

float FramePipeline::fall_back_for_memory(int step, float lod_error_px) {
  if (step == 1) {
    // The list buffers the renderer holds, so a frame's passes need no growth.
    const std::uint64_t held = renderer_->buffer_shape().list_entries * kListBytesPerEntry;
    limit_list_budget(std::min(held, renderer_->options().list_budget.max_bytes));
    return lod_error_px;
  }
  if (!cut_counter_) return lod_error_px;  // no LOD: nothing coarser to draw
  const float bound = std::max(lod_error_px, 1.0f) * 2.0f;
  RenderOptions o = renderer_->options();
  o.lod_error_px = bound;  // this frame only: the next job's set_lod_bound sets its own
  renderer_->set_options(o);
  return bound;
}

FramePipeline::JobResult FramePipeline::failure_of(const Rendered& frame) {
  JobResult failed;
  failed.record = frame.record;  // its error fields with the rest of its record
  return failed;
}

FramePipeline::JobResult FramePipeline::take_failed(Rendered&& frame) {
  free_planes_.push_back(std::move(frame.planes));
  return failure_of(frame);
}

void FramePipeline::drop_rendered() {
  free_planes_.push_back(std::move(rendered_->planes));
  rendered_.reset();
}

std::shared_ptr<FramePipeline::Rendered> FramePipeline::start_encode() {
  encoding_ = true;
  rendered_->job.frame_sequence = next_frame_sequence_++;  // in encode (= send) order, no gaps
  auto frame = std::make_shared<Rendered>(std::move(*rendered_));
  rendered_.reset();
  return frame;
}

void FramePipeline::end_encode(Rendered& frame) {
  encoding_ = false;
  free_planes_.push_back(std::move(frame.planes));
}

float FramePipeline::set_lod_bound(const Camera& camera) {
  if (!cut_counter_) return 0.0f;  // no LOD: the bound means nothing
  const LodSettings& lod = settings_.lod;
  const float base = size_scaled_lod_bound(lod.bound_px, camera.width, camera.height, lod.reference_lines);
  std::uint64_t budget = lod.splat_budget;
  if (budget == 0 && lod.auto_budget && gpu_ >= 0)
    budget = auto_splat_budget(metrics_.gpu_splats_per_ms(gpu_), metrics_.gpu_sessions(gpu_), lod.budget_share);
  const float tau = lod_bound_.choose(*cut_counter_, camera, base, budget, lod.max_steps());
  // At the ceiling and still over the budget: this GPU holds no more visitors at the picture's
  // floor; the door reads it (Session::on_scene_ready).
  if (lod_bound_.over_budget()) metrics_.lod_over_budget_frames_total++;
  if (lod_bound_.over_budget_streak() >= LodBoundChooser::kShortStreak)
    metrics_.note_gpu_budget_short(gpu_, ServerMetrics::steady_now_ms());
  if (renderer_->options().lod_error_px != tau) {
    RenderOptions o = renderer_->options();
    o.lod_error_px = tau;  // a catgs group closes: its key frame's cut is the group's
    renderer_->set_options(o);
  }
  return tau;
}

void FramePipeline::begin_render_into(const Job& job, const Yuv420Target& target, Rendered& r) {
  r.render_started = Clock::now();
  r.record.queue_ms = ms_between(job.pose.received, r.render_started);
  r.record.lane_wait_ms = ms_between(job.posted_at, r.render_started);
  r.record.render_lane = RenderScheduler::current_lane();
  const Camera camera = camera_of(job);
  const double cpu0 = thread_cpu_ms();
  r.record.lod_error_px = job.lod_error_px >= 0.0f ? job.lod_error_px : set_lod_bound(camera);
  const double cpu1 = thread_cpu_ms();
  r.record.lod_cpu_ms = cpu1 - cpu0;
  // Frames on this GPU from the begin to the finish (the throughput model's sharing count).
  r.gpu_frames_at_begin = gpu_ >= 0 ? metrics_.gpu_render_begin(gpu_) : 1;
  // The server's list budget again, a while after a memory fallback lowered it.
  if (frames_since_fallback_ >= 0 && ++frames_since_fallback_ > kMemoryRestoreFrames) {
    RenderOptions o = renderer_->options();
    o.list_budget = server_list_budget_;
    renderer_->set_options(o);
    frames_since_fallback_ = -1;
  }
  for (int step = 0;; ++step) {
    try {
      begin_views(job, camera, target, r);
      break;
    } catch (...) {
      // A buffer that could not grow: the same frame again, in passes or coarser (issue 73). The
      // renderer is whole after the throw (base/allocation_faults.h).
      const bool retry = step < kMemoryFallbacks && out_of_memory_in_flight();
      if (!retry) {
        if (gpu_ >= 0) metrics_.gpu_render_end(gpu_);
        throw;
      }
      try {
        throw;
      } catch (const std::exception& e) {
        r.record.memory_note = e.what();
      }
      r.record.memory_fallback = step + 1;
      r.record.lod_error_px = fall_back_for_memory(step + 1, r.record.lod_error_px);
    }
  }
  if (r.record.memory_fallback > 0) metrics_.render_memory_fallbacks_total++;  // drawn after all
  r.record.begin_cpu_ms = thread_cpu_ms() - cpu1;
  r.render_begun = true;
}

void FramePipeline::begin_views(const Job& job, const Camera& camera, const Yuv420Target& target, Rendered& r) {
  // Rendered and colour-converted where the frame is (on the GPU for the CUDA core: a host
  // target gets only the I420 planes). The client's clock drives the catgs motion predictor.
  const double time_s = job.pose.client_time_ms / 1000.0;
  if (!job.pose.eyes) {
    renderer_->begin_yuv420_at(camera, time_s, target);
    return;
  }
  // A headset: each eye into its half, one after the other on the session's renderer (the
  // occlusion map the right eye reads is the left eye's; issue 94).
  const std::array<Camera, 2> eyes = eye_cameras(job);
  const int w = eyes[0].width;
  renderer_->begin_yuv420_at(eyes[0], time_s, columns_of(target, 0, w));
  r.record.convert_ms = renderer_->finish_yuv420();
  r.record.frame = renderer_->last_stats();
  renderer_->begin_yuv420_at(eyes[1], time_s, columns_of(target, w, w));
}

void FramePipeline::finish_render_into(Rendered& r) {
  r.render_begun = false;
  const double cpu0 = thread_cpu_ms();
  double frames_with_it = 1.0;
  const bool stereo = r.job.pose.eyes.has_value();
  double convert_ms = 0;
  try {
    convert_ms = renderer_->finish_yuv420();
  } catch (...) {
    if (gpu_ >= 0) metrics_.gpu_render_end(gpu_);
    throw;
  }
  if (gpu_ >= 0) frames_with_it = 0.5 * (r.gpu_frames_at_begin + metrics_.gpu_render_end(gpu_));
  r.record.convert_ms = stereo ? r.record.convert_ms + convert_ms : convert_ms;
  r.record.frame = stereo ? both_eyes(r.record.frame, renderer_->last_stats()) : renderer_->last_stats();
  r.record.buffer_bytes = renderer_->device_buffer_bytes();
  r.record.buffer_shape = renderer_->buffer_shape();
  const DepthGrid& depth = renderer_->last_depth_grid();
  r.record.depth_grid.Clear();
  // A stereo frame carries no grid: the renderer's is the right eye's alone (the page warps each
  // eye by the plane).
  if (depth.cols > 0 && !stereo) pack_depth_grid(depth, &r.record.depth_grid);
  // Render time includes the plane download (GPU) but not the conversion itself; with frames in
  // flight, also the time the lane spent beginning other frames before this one's finish.
  r.record.render_ms = std::max(0.0, ms_between(r.render_started, Clock::now()) - r.record.convert_ms);
  // A sub-frame's time is not its Gaussians' (the caches skip the pre-process). With occlusion
  // culling the frame draws fewer Gaussians than the cut holds, while the splat budget is held
  // against the cut's prediction: the throughput is then counted in the prediction's Gaussians
  // (render/lod_bound.h), else the budget would shrink with every Gaussian the culling saves.
  const std::uint64_t throughput_splats =
      renderer_->options().occlusion_culling
          ? std::max<std::uint64_t>(r.record.frame.visible, lod_bound_.predicted_splats())
          : r.record.frame.visible;
  if (gpu_ >= 0 && r.record.frame.key_frame)
    metrics_.observe_gpu_throughput(gpu_, throughput_splats, r.record.render_ms, frames_with_it);
  r.record.finish_cpu_ms = thread_cpu_ms() - cpu0;
}

void FramePipeline::render_into(const Job& job, const Yuv420Target& target, Rendered& r) {
  begin_render_into(job, target, r);
  finish_render_into(r);
}

void FramePipeline::note_failure(Rendered& r) {
  try {
    throw;
  } catch (const RenderBudgetError& e) {
    r.record.error = e.what();
    r.record.over_budget = true;
  } catch (const OutOfMemoryError& e) {
    r.record.error = e.what();
    r.record.out_of_memory = true;
    r.record.buffer_bytes = renderer_->device_buffer_bytes();
    r.record.buffer_shape = renderer_->buffer_shape();
  } catch (const cuda::CudaError& e) {
    r.record.error = e.what();
    r.record.out_of_memory = e.code() == kCudaOutOfMemory;
    r.record.buffer_bytes = renderer_->device_buffer_bytes();
    r.record.buffer_shape = renderer_->buffer_shape();
  } catch (const std::exception& e) {
    r.record.error = e.what();
  } catch (...) {
    r.record.error = "unknown error";
  }
}

FramePipeline::Rendered FramePipeline::begin_render(Job job, std::unique_ptr<Yuv420Image> planes, bool gone) {
  Rendered r;
  r.job = std::move(job);
  r.planes = std::move(planes);
  if (gone) {  // nobody to send it to: the lane moves on to the next session at once
    r.record.error = "session gone";
    return r;
  }
  try {
    begin_render_into(r.job, r.planes->target(r.job.shape.width, r.job.shape.height), r);
  } catch (...) {
    note_failure(r);
  }
  return r;
}

bool FramePipeline::frame_ready() const {
  try {
    return renderer_->frame_ready();
  } catch (...) {
    return true;
  }
}

void FramePipeline::finish_render(Rendered& frame) {
  if (!frame.render_begun) return;  // failed or skipped at its begin
  try {
    finish_render_into(frame);
  } catch (...) {
    note_failure(frame);
  }
}

FramePipeline::JobResult FramePipeline::encode(Rendered& frame) {
  try {
    bool idr = frame.job.force_idr;
    const FrameEncoding settings = encoder_.prepare(frame.job.shape, frame.job.pose.refine, idr);
    const EncodedFrame enc = encoder_.encoder().encode_yuv420(frame.planes->planes(), idr);
    encoder_.probe_content_rate(frame.job.shape, frame.job.pose.pose, settings, frame.planes->planes());
    JobResult result = frame_message(frame.job, enc, frame);
    result.link_ceiling_kbps = settings.link_ceiling_kbps;
    return result;
  } catch (const std::exception& e) {
    // The frame's record stays with it (what was drawn, the buffers the session holds: the
    // strand reads them from every result), with the encoder's reason.
    JobResult r;
    r.record = frame.record;
    r.record.error = e.what();  // the encoder names itself ("x264: ...")
    return r;
  }
}

FramePipeline::JobResult FramePipeline::render_and_encode(const Job& job, bool gone) {
  Rendered r;
  r.job = job;  // finish_render_into reads whether it is a stereo frame
  if (gone) {
    r.record.error = "session gone";
    return failure_of(r);
  }
  try {
    bool idr = job.force_idr;
    const FrameEncoding settings = encoder_.prepare(job.shape, job.pose.refine, idr);
    // Straight into the encoder's input planes: the hw frame's device memory for NVENC.
    render_into(job, encoder_.encoder().input_target(), r);
    JobResult result = frame_message(job, encoder_.encoder().encode_input(idr), r);
    result.link_ceiling_kbps = settings.link_ceiling_kbps;
    return result;
  } catch (...) {
    note_failure(r);
  }
  return failure_of(r);
}

FramePipeline::JobResult FramePipeline::frame_message(const Job& job, const EncodedFrame& enc,
                                                      const Rendered& rendered) {
  JobResult r;
  r.record = rendered.record;  // the frame's record, whole
  r.encode_ms = enc.encode_ms;
  r.encode_psnr_db = enc.psnr_db;
  r.encode_thread_cpu_ms = enc.thread_cpu_ms;
  r.encoder = encoder_.label();
  r.total_ms = ms_between(job.pose.received, Clock::now());
  r.quality_level = job.shape.quality_level;
  r.refine = job.pose.refine;
  r.predicted = job.pose.predicted;
  r.rate_capped = !job.pose.refine && encoder_.rate_capped();
  const bool lifted_cap = encoder_.take_refine_lifted_cap();
  r.refine_vbv_bound = job.pose.refine && lifted_cap;
  pb::ServerMessage m;
  pb::Frame* f = m.mutable_frame();
  f->set_sequence(job.frame_sequence);
  f->set_pose_sequence(job.pose.sequence);
  f->set_client_time_ms(job.pose.client_time_ms);
  if (job.pose.predicted) {  // Frame.shown_pose: the page re-projects from it, not from its Pose
    pb::Pose* shown = f->mutable_shown_pose();
    const CameraPose& p = job.pose.pose;
    set_pose(p.position, p.orientation, shown->mutable_position(), shown->mutable_orientation());
    shown->set_vertical_fov_deg(p.vertical_fov_deg);
  }
  if (job.pose.eyes) {  // a headset's frame says the eyes its halves show
    set_eye(job.pose.eyes->left, f->mutable_left_eye());
    set_eye(job.pose.eyes->right, f->mutable_right_eye());
    f->set_eye_width(static_cast<std::uint32_t>(job.shape.width / 2));
  }
  f->set_key_frame(enc.key_frame);
  f->set_width(static_cast<std::uint32_t>(job.shape.width));
  f->set_height(static_cast<std::uint32_t>(job.shape.height));
  f->set_payload(enc.data.data(), enc.data.size());
  if (r.record.depth_grid.cols() > 0) *f->mutable_depth_grid() = r.record.depth_grid;
  f->set_codec(encoder_.encoder().codec() == "av1" ? pb::CODEC_AV1 : pb::CODEC_H264);
  // FrameTimings: the record's times and render outcome, here and nowhere else.
  pb::FrameTimings* t = f->mutable_timings();
  t->set_queue_ms(r.record.queue_ms);
  t->set_lane_wait_ms(r.record.lane_wait_ms);
  t->set_render_ms(r.record.render_ms);
  t->set_convert_ms(r.record.convert_ms);
  t->set_encode_ms(r.encode_ms);
  t->set_encode_psnr_db(static_cast<float>(r.encode_psnr_db));
  t->set_encode_thread_cpu_ms(r.encode_thread_cpu_ms);
  t->set_total_ms(r.total_ms);
  t->set_previous_send_ms(job.shape.previous_send_ms);
  t->set_render_key_frame(r.record.frame.key_frame);
  t->set_render_rekey(r.record.frame.subframe_rejected);
  t->set_speculation_predicted_gain(static_cast<float>(r.record.frame.predicted_gain));
  t->set_speculation_measured_gain(static_cast<float>(r.record.frame.measured_gain));
  t->set_speculation_window(static_cast<std::uint32_t>(std::max(0, r.record.frame.window)));
  t->set_lod_error_px(r.record.lod_error_px);
  t->set_splats(static_cast<std::uint32_t>(std::min<std::uint64_t>(r.record.frame.visible, UINT32_MAX)));
  t->set_stage_frame_ms(r.record.frame.total_ms);
  t->set_stage_preprocess_ms(r.record.frame.preprocess_ms);
  t->set_stage_keys_ms(r.record.frame.keys_ms);
  t->set_stage_sort_ms(r.record.frame.sort_ms);
  t->set_stage_ranges_ms(r.record.frame.ranges_ms);
  t->set_stage_rasterize_ms(r.record.frame.rasterize_ms);
  t->set_render_lane(static_cast<std::uint32_t>(std::max(0, r.record.render_lane)));
  t->set_lane_lod_cpu_ms(r.record.lod_cpu_ms);
  t->set_lane_begin_cpu_ms(r.record.begin_cpu_ms);
  t->set_lane_finish_cpu_ms(r.record.finish_cpu_ms);
  m.SerializeToString(&r.message);
  r.key_frame = enc.key_frame;
  r.payload_bytes = enc.data.size();
  r.frame_sequence = job.frame_sequence;
  r.link_read_at = job.shape.link_read_at;
  return r;
}

}  // namespace catgs::server
