// catgs-bench's timing loop: each variant renders the same trace frames, one variant after the
// other, in this process. CUDA: CUDA events on the renderer's stream around render_device_at()
// (pose in, image in device memory out), and optionally each K-th catgs frame compared, after its
// timing, with a full exact render of the same pose. CPU reference: the steady clock around
// render_at() (pose in, 8-bit image in host memory out).
#pragma once

#include <cstddef>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "bench/variants.h"
#include "camera/trace.h"
#include "renderer/renderer.h"

namespace catgs::cuda {
class DeviceScene;
}

namespace catgs::bench {

// One variant's timed frames: per-frame records, and for catgs the key / sub-frame split.
struct PipelineResult {
  std::string name;  // the variant as written
  Pipeline pipeline = Pipeline::exact;
  std::vector<double> frame_ms, pre, keys, sort, ranges, raster, list, visible, heaviest;
  std::vector<double> chunks;  // chunks pre-processed (FrameStats::chunks_preprocessed)
  // Issue 72's measurement of where the list's work goes: entries behind their tile's opaque
  // point (exact-occlusion), and with --count-changes (CPU) the entries and Gaussians that change
  // a pixel.
  std::vector<double> behind_opaque, changing_entries, changing_gaussians;
  std::vector<double> preprocessed, hidden_chunks, hidden_groups, hidden_alone,
      entries_hidden_px;                       // cpu::count_hidden's
  std::vector<double> key_ms, sub_ms, window;  // catgs: key vs sub-frame times, W per key frame
  // catgs: key frames drawn after a rejected sub-frame, and key frames without a window (W = 0).
  std::vector<double> rejected_ms, full_ms;
  struct Groups {
    std::size_t count = 0, served = 0, rejected = 0;  // groups, sub-frames served, ended by a rejection
  };
  std::map<int, Groups> groups;  // catgs: by W, the groups that closed during the timed frames
  int open_window = 0;           // the open group's W (0: none), and its sub-frames so far
  std::size_t open_served = 0;
  std::vector<double> key_stage[6], sub_stage[6];          // catgs: pre, keys, sort, ranges, raster, merge
  std::vector<double> sub_psnr, sub_max_abs, list_growth;  // catgs vs exact, same pose (--quality-every)
  std::size_t subframes_inf = 0;                           // sub-frames identical to the full render (PSNR +inf)
  // A scene with LOD and --quality-every: every compared frame (any pipeline, key or sub-frame)
  // against the full-detail exact render of the same pose (lod_error_px 0), PSNR over 8-bit RGB.
  std::vector<double> lod_psnr;
  std::size_t lod_identical = 0;  // of those, identical (PSNR +inf)
  // With --aa-reference F as well: the same frames, and the full-detail render of their pose,
  // against the anti-aliased reference (full detail at F times the size, box-filtered down:
  // common/image_io.h box_downsample). PSNR over 8-bit RGB (+inf kept: an identical frame).
  std::vector<double> lod_psnr_aa, full_psnr_aa;
  std::size_t peak_buffer_bytes = 0, device_used_bytes = 0, allocations_timed = 0;  // CUDA
  int syncs = 0;                                                                    // CUDA
};

// Appends one timed frame (its time, stage times and counters); a key frame closes the open group
// and opens the next one.
void record_frame(PipelineResult& result, double ms, const FrameStats& stats);

// The frames every variant renders: `warmup` untimed, then `frames` timed, frame k being the
// trace's camera k (cycled) posed at k / pose_rate_hz s (--pose-rate; the trace's own 120 FPS by
// default: a lower rate keeps the motion a frame and stretches the clock, as a session sending
// fewer poses a second over the same path per pose).
struct TimingPlan {
  const Trace* trace = nullptr;
  int warmup = 30, frames = 600;
  int quality_every = 1;  // CUDA: compare every K-th timed catgs frame with exact (0: never)
  float lod_error_px = RenderOptions{}.lod_error_px;  // every variant's LOD bound (renderer.h)
  bool lod = false;   // the scene has LOD: every K-th frame of every variant, on both cores, against full detail
  int aa_factor = 0;  // >= 2 (with lod): those frames also against the anti-aliased reference
  bool count_changes = false;  // CPU: measure the entries and Gaussians that change a pixel (slow)
  std::string snapshot_dir;    // not empty: a PNG per variant there
  Camera camera_at(int k) const { return (*trace)[static_cast<std::size_t>(k) % trace->size()].camera; }
  double pose_rate_hz = 120.0;
  double time_at(int k) const { return k / pose_rate_hz; }
};

// The CPU reference over `model`; a snapshot is the last timed frame
// (DIR/SCENE_cpu_VARIANT.png).
// `reference` (null: `model`) draws the full-detail and anti-aliased references (catgs-bench
// --compact: the float scene, against which the quantized one is timed and compared).
std::vector<PipelineResult> time_on_cpu(const std::shared_ptr<const GaussianModel>& model,
                                        const std::vector<Variant>& variants, const TimingPlan& plan,
                                        const std::shared_ptr<const GaussianModel>& reference = nullptr);

#if CATGS_HAVE_CUDA
// The CUDA core over `scene`, one CudaRenderer per variant; device_used_bytes counts from
// `used_before_scene` (device memory in use before the scene was uploaded). A snapshot is the
// middle timed pose rendered again after timing (DIR/SCENE_VARIANT.png).
std::vector<PipelineResult> time_on_cuda(const std::shared_ptr<const cuda::DeviceScene>& scene,
                                         const std::vector<Variant>& variants, const TimingPlan& plan,
                                         std::size_t used_before_scene,
                                         const std::shared_ptr<const cuda::DeviceScene>& reference = nullptr);
#endif

}  // namespace catgs::bench
