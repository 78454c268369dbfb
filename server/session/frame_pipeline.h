// A session's frames from pose to Frame message (docs/DESIGN.md "Data flow of a frame"): the
// newest pose waiting (latest wins), the render job that renders it and converts it to I420
// where it was rendered, the rendered picture waiting for the encoder, the encode job that makes
// it an access unit (H.264, or AV1 for a client that decodes it where the encoder policy affords
// it: encode/encoder_policy.h use_av1), and the serialized Frame. The unit owns the frame's state: the pose
// slots, the two host I420 buffers, the session's renderer (the render side: poses, the level of
// detail, the memory fallback, a headset's two eyes; here) and its encoder (the encode side: the
// encoder's life, its rate, the content-rate probe; StreamEncoder, stream_encoder.h). The session's
// stream (SessionStream, session_stream.h) decides when a stage may start (protocol state, frames
// in flight, pacing, adaptive quality, the link's cap) and posts the jobs.
//
// Pipelined (host-fed encoders: x264): a render job renders and colour-converts frame n + 1 into
// one of two host I420 buffers while an encode job encodes frame n from the other, so a session's
// frame rate is bounded by the slower stage, not by their sum. NVENC with the CUDA renderer: one
// job renders straight into the encoder's hw frame and encodes it (no host buffer to overlap).
//
// Threading: the functions under "strand" are called on the session's strand only; those under
// "jobs" in a render job (a render lane) or an encode job (the worker pool), at most one of each
// at a time, never on the strand. The renderer is used only by render jobs, the encoder only by
// encode jobs (the one-job path: by its one job). Errors: the job functions never throw; a
// failure comes back in the result's `error`.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "encode/content_rate.h"
#include "encode/encoder.h"
#include "encode/frame_encoding.h"
#include "proto/message_validation.h"
#include "renderer/renderer.h"
#include "process/server_metrics.h"
#include "render/lod_bound.h"
#include "session/session_settings.h"
#include "session/stream_encoder.h"

namespace catgs::server {

// Milliseconds from a to b.
inline double ms_between(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

class FramePipeline {
 public:
  using Clock = std::chrono::steady_clock;

  // A validated pose waiting to be rendered.
  struct PendingPose {
    CameraPose pose;  // the pose to render: the client's, or where it will be (pose_prediction.h)
    CameraPose sent;  // the client's Pose (a refine frame draws it: a still camera is there)
    // A headset's eyes (Pose.left_eye, right_eye; issue 94): the frame shows both, side by side.
    std::optional<StereoPose> eyes;
    bool predicted = false;  // pose is not `sent`: the Frame says which pose it shows
    std::uint32_t sequence = 0;
    double client_time_ms = 0;
    Clock::time_point received;  // arrival on the transport thread
    // The still view's refine frame (still_refine.h): full size whatever the adaptive level,
    // encoded at the stream's crf with no rate cap (kRefineKbps).
    bool refine = false;
  };
  // What a render job is asked for, as the session decided it (stream_encoder.h).
  using JobShape = server::JobShape;
  struct Job {
    PendingPose pose;
    JobShape shape;
    bool force_idr = false;
    std::uint32_t frame_sequence = 0;
    // The LOD bound chosen for the pose when the job was made (start_render, on the strand: the
    // cut's count walks the LOD tree on the host, work a render lane need not wait for); < 0: the
    // lane chooses it.
    float lod_error_px = -1.0f;
    Clock::time_point posted_at{};  // when the job was made and posted to the render lanes
  };
  // What rendering made of a frame (issue 75: the frame's record, carried whole, a member of
  // Rendered and then of JobResult, from the render job to the encode job and to the strand,
  // where Stats and /metrics read it; FrameTimings is filled from it in one place, frame_message).
  struct RenderRecord {
    // The renderer's own record of the frame, whole (renderer.h): a key frame or a catgs
    // sub-frame, a re-key, the cost model's gains, the window, the Gaussians that passed culling
    // (visible), the stage times.
    FrameStats frame;
    float lod_error_px = 0;  // the LOD bound the frame drew at (0: full detail or no LOD)
    double queue_ms = 0, render_ms = 0, convert_ms = 0;
    double lane_wait_ms = 0;  // of queue_ms: posted -> its lane began it (FrameTimings.lane_wait_ms)
    int render_lane = -1;     // the render lane that drew it (-1: none)
    // The lane thread's CPU in the frame's steps, ms (FrameTimings.lane_*_cpu_ms; base/thread_clock.h).
    double lod_cpu_ms = 0, begin_cpu_ms = 0, finish_cpu_ms = 0;
    std::string error;               // non-empty: the render (or, in a JobResult, the encode) failed
    bool over_budget = false;        // it failed with RenderBudgetError (renderer.h): the view, not the server
    bool out_of_memory = false;      // it failed because a device buffer could not grow (issue 61)
    std::uint64_t buffer_bytes = 0;  // the renderer's device buffers after it (Renderer::device_buffer_bytes)
    BufferShape buffer_shape;        // what they hold (Renderer::buffer_shape)
    // A buffer could not grow and the frame was drawn anyway (issue 73; memory_fallback): in passes
    // within the list buffers held (1), or also at a coarser cut (2, 3). 0: it fitted. The note
    // says what could not grow.
    int memory_fallback = 0;
    std::string memory_note;
    pb::DepthGrid depth_grid;  // Frame.depth_grid (cols 0: none; proto/depth_grid_coding.h)
  };
  // A rendered frame waiting for (or in) the encode stage.
  struct Rendered {
    Job job;
    RenderRecord record;
    std::unique_ptr<Yuv420Image> planes;  // null for the one-job (NVENC) path
    // Between begin_render and finish_render: the frame is queued on the renderer.
    bool render_begun = false;
    Clock::time_point render_started{};  // when its lane began it
    int gpu_frames_at_begin = 1;         // frames on its GPU then (ServerMetrics::gpu_render_begin)
  };
  // A finished frame (or why there is none): its render record and what the encode made of it.
  struct JobResult {
    RenderRecord record;     // the frame's, from its render job (with the encode's error where it failed)
    std::string message;     // serialized ServerMessage{Frame}; empty on failure
    bool key_frame = false;  // an IDR access unit
    std::size_t payload_bytes = 0;
    std::uint32_t frame_sequence = 0;                      // Frame.sequence
    std::chrono::steady_clock::time_point link_read_at{};  // JobShape's: the rate it was encoded at
    int link_ceiling_kbps = 0;  // the frame's FrameEncoding::link_ceiling_kbps (what the link's controller caps)
    double encode_ms = 0;
    double encode_psnr_db = 0;        // EncodedFrame::psnr_db (FrameTimings.encode_psnr_db)
    double encode_thread_cpu_ms = 0;  // EncodedFrame::thread_cpu_ms (FrameTimings.encode_thread_cpu_ms)
    std::string encoder;              // Stats.encoder: the encoder that coded it ("x264 superfast")
    double total_ms = 0;              // pose received -> frame handed off (FrameTimings.total_ms)
    int quality_level = 0;
    bool refine = false;       // the still view's refine frame
    bool predicted = false;    // drawn at a predicted pose (pose_prediction.h), not the client's
    bool rate_capped = false;  // encoded under a VBV rate (the policy's, a client's, the link's cap)
    // A refine frame that lifted x264's VBV cap: x264 keeps the buffer's fill across a new rate,
    // so it was planned against what the capped frames left; the next reaches the crf
    // (still_refine.h).
    bool refine_vbv_bound = false;
  };
  // A render job to post: the job and, pipelined, the host buffer it renders into.
  struct StartedRender {
    Job job;
    std::unique_ptr<Yuv420Image> planes;
  };

  // `settings` and `metrics` outlive the pipeline (the server holds them).
  FramePipeline(const FrameSettings& settings, ServerMetrics& metrics)
      : settings_(settings), metrics_(metrics), encoder_(settings, metrics) {}
  FramePipeline(const FramePipeline&) = delete;
  FramePipeline& operator=(const FramePipeline&) = delete;

  // --- strand ---
  // At Welcome: the session's renderer of `model` (which outlives the pipeline), on CUDA device
  // `gpu` (-1: the CPU renderer), whether render and encode are two stages (false: NVENC
  // takes the CUDA frame in one job), and whether the stream may be AV1 (`av1_ok`: the client
  // decodes it and the server's encoders are x264's CPU ones), and the scene's probed rate caps
  // (`content_rates`, the LoadedScene's; null: the policy's bits a pixel alone).
  void open(std::unique_ptr<Renderer> renderer, std::shared_ptr<const GaussianModel> model, int gpu, bool pipelined,
            bool av1_ok, std::shared_ptr<ContentRates> content_rates = nullptr);
  // Whether a stream of `shape` at `live_sessions` sessions would be AV1 now (the encoder policy's
  // use_av1): Welcome.codec before the first frame.
  bool stream_is_av1(const JobShape& shape, int live_sessions) const {
    return encoder_.stream_is_av1(shape, live_sessions);
  }
  std::string renderer_name() const { return renderer_ ? renderer_->name() : std::string(); }
  bool pipelined() const { return pipelined_; }

  // Latest pose wins: `pose` replaces any pose not yet started.
  void offer(const PendingPose& pose) { pending_ = pose; }
  const std::optional<PendingPose>& pending() const { return pending_; }
  // Forgets the waiting pose; true when there was one (it will never be rendered).
  bool drop_pending();
  // The next frame is an IDR (a new size, a key-frame request, a new bitrate).
  void request_idr() { force_idr_ = true; }
  // The still view's refine frame (still_refine.h): the last pose started, once more, when no
  // pose waits. can_refine() says whether there is one; refine() queues it.
  bool can_refine() const { return !pending_ && last_started_; }
  void refine(Clock::time_point now);
  // A frame lost because its buffers could not grow (issue 73): its pose waits again where no
  // newer pose does, so a still camera gets its picture (it sends no other pose). Returns whether
  // one waits now.
  bool retry_lost() {
    if (!pending_ && last_started_) pending_ = last_started_;
    return pending_.has_value();
  }

  // Whether a render job may start: none running, the rendered slot empty, a pose waiting and,
  // pipelined, a host buffer free.
  bool can_start_render() const;
  // Takes the waiting pose into a render job of `shape` (can_start_render() must hold).
  StartedRender start_render(const JobShape& shape);
  // Every render job's end, first thing on the strand.
  void end_render() { rendering_ = false; }
  // After a frame whose device buffers could not grow (issue 61): halves the renderer's
  // render-list budget (RenderListBudget::max_bytes, at least kMinListBytes), so its later frames
  // are drawn in passes within the list buffers it has. Returns the new budget, bytes. Only
  // between render jobs.
  static constexpr std::uint64_t kMinListBytes = 32ull << 20;
  std::uint64_t halve_list_budget();
  // A frame whose buffer could not grow is drawn again within the same job, up to
  // kMemoryFallbacks times (issue 73: a growth that fails drops no frame): first in passes within
  // the list buffers the renderer holds, then at twice and four times the LOD bound (a scene with
  // LOD). The lowered list budget stays for kMemoryRestoreFrames frames, then the server's budget
  // is tried again.
  static constexpr int kMemoryFallbacks = 3;
  // A list budget in bytes a core's list buffers of N entries hold at least: the fewer of the
  // cores' bytes an entry (cuda/cuda_renderer.h kBytesPerListEntry 24, cpu/cpu_renderer.h 28).
  static constexpr std::uint64_t kListBytesPerEntry = 24;
  static constexpr int kMemoryRestoreFrames = 600;
  // A render that failed: its buffer back, and the result that reports it.
  JobResult take_failed(Rendered&& frame);
  // A rendered frame into the slot the encode stage takes from.
  void store_rendered(Rendered&& frame) { rendered_ = std::move(frame); }
  bool encoding() const { return encoding_; }
  const std::optional<Rendered>& rendered() const { return rendered_; }
  // The rendered frame is not encoded (skipped, or nobody to send it to): its buffer back.
  void drop_rendered();
  // Takes the rendered frame into an encode job, numbered in encode (= send) order.
  std::shared_ptr<Rendered> start_encode();
  // An encode job's end: its buffer back.
  void end_encode(Rendered& frame);

  // --- jobs ---
  // Begins rendering `job` into `planes` (a render lane; Renderer::begin_yuv420_at): the frame is
  // queued on the renderer; `gone`: the session ended, skip the work. finish_render completes it,
  // before any other use of this session's renderer.
  Rendered begin_render(Job job, std::unique_ptr<Yuv420Image> planes, bool gone);
  // Waits for a begun frame's planes and fills its render fields (timings, key frame, window); a
  // frame that failed or was skipped at its begin is left as it is. A failure comes back in
  // `frame.error`.
  void finish_render(Rendered& frame);
  // Whether a begun frame's finish_render would not wait for the renderer (Renderer::frame_ready;
  // an error reads as ready, for the finish to report). The lane's thread; no wait.
  bool frame_ready() const;
  // Encodes a rendered frame into a Frame message (the worker pool).
  JobResult encode(Rendered& frame);
  // The one-job path: renders into the encoder's input and encodes it (a render lane).
  JobResult render_and_encode(const Job& job, bool gone);

 private:
  // Renders job's pose into `target` and fills r's render fields (timings, key frame, window):
  // begin_render_into then finish_render_into. Throw what Renderer::render_yuv420_at throws.
  void render_into(const Job& job, const Yuv420Target& target, Rendered& r);
  void begin_render_into(const Job& job, const Yuv420Target& target, Rendered& r);
  void finish_render_into(Rendered& r);
  // Inside a catch block: the exception in flight as r's error fields (over budget, out of
  // device memory, other).
  void note_failure(Rendered& r);
  // A failed frame's result: its error fields.
  static JobResult failure_of(const Rendered& frame);
  // Inside a catch block: whether the exception in flight says a buffer could not grow
  // (OutOfMemoryError, or a CudaError cudaErrorMemoryAllocation from elsewhere in the core).
  static bool out_of_memory_in_flight();
  // Memory fallback `step` (1..kMemoryFallbacks) for a frame at LOD bound `lod_error_px`: the list
  // budget lowered to the list buffers held (step 1), then also the bound doubled (2) and doubled
  // again (3) where the scene has LOD. Returns the bound the frame is drawn at.
  float fall_back_for_memory(int step, float lod_error_px);
  // The renderer's list budget set to `max_bytes` (at least kMinListBytes), its passes raised so
  // that a frame the server's budget draws still fits in them. Returns the budget set.
  std::uint64_t limit_list_budget(std::uint64_t max_bytes);
  // The frame's LOD bound (render/lod_bound.h) set on the renderer where it changed; called when
  // the job is made (start_render, on the strand, no render of the session running), or by the
  // lane where that failed.
  float set_lod_bound(const Camera& camera);
  // The camera of a job's pose at its shape's size; a stereo job's: its left eye's (the level of
  // detail's bound is chosen once for both eyes).
  static Camera camera_of(const Job& job);
  // A stereo job's eyes (issue 94): left and right at an eye's size (the shape's width / 2).
  static std::array<Camera, 2> eye_cameras(const Job& job);
  // Queues a job's frame on the renderer into `target`: one view, or a stereo job's two eyes into
  // the target's halves (the left eye drawn and waited for here, the right eye queued; r's
  // convert_ms and frame hold the left eye's until finish_render_into adds the right eye's).
  void begin_views(const Job& job, const Camera& camera, const Yuv420Target& target, Rendered& r);
  JobResult frame_message(const Job& job, const EncodedFrame& enc, const Rendered& r);

  const FrameSettings& settings_;
  ServerMetrics& metrics_;

  // --- strand state ---
  std::optional<PendingPose> pending_;
  std::optional<PendingPose> last_started_;  // the pose of the last render started (refine frames)
  bool force_idr_ = true;
  bool rendering_ = false;                                 // a render (or render-and-encode) job is running
  bool encoding_ = false;                                  // an encode job is running
  bool pipelined_ = true;                                  // render and encode as separate stages
  std::optional<Rendered> rendered_;                       // rendered, waiting for the encoder
  std::vector<std::unique_ptr<Yuv420Image>> free_planes_;  // the two I420 buffers when idle
  std::uint32_t next_frame_sequence_ = 0;

  // --- job state (one render job and one encode job at a time) ---
  std::unique_ptr<Renderer> renderer_;
  std::shared_ptr<const GaussianModel> model_;
  std::unique_ptr<CutCounter> cut_counter_;  // built at open for a model with LOD
  LodBoundChooser lod_bound_;
  RenderListBudget server_list_budget_;  // the renderer's at open; restored after a memory fallback
  int frames_since_fallback_ = -1;       // frames since the list budget was lowered (-1: it is not)
  int gpu_ = -1;                         // the CUDA device renderer_ renders on, -1: none (CPU renderer)
  StreamEncoder encoder_;                // the encode side: the encoder's life, its rate, the content-rate probe
};

}  // namespace catgs::server
