// Device-memory accounting (issue 61; docs/DESIGN.md "Device memory"): what a scene's copy and a
// session's render buffers take on a GPU, worked out on the host before anything is allocated, so
// the server admits a session only where a GPU can hold it. The CPU core uses the same accounting
// (the server's --device-memory-mb allowance), so admission is tested without a GPU.
//
// The byte counts mirror the CUDA core's buffers (cuda/renderer_state.h, ensure_frame_buffers and
// ensure_catgs_buffers; cuda/device_scene.cpp): a change there changes them here, and the GPU test
// DeviceMemory.EstimateBoundsTheBuffers holds the estimate to the buffers a real frame grew.
#pragma once

#include <cstdint>

#include "renderer/renderer.h"
#include "scene/gaussian_model.h"

namespace catgs {

// Device bytes of one copy of `model` (cuda::DeviceScene): float32 means, log-scales, rotations
// and opacities, half-precision SH, one chunk bound per chunk and the LOD nodes.
std::uint64_t scene_device_bytes(const GaussianModel& model);

// What a session's buffers are sized by.
struct SessionBufferShape {
  std::uint64_t gaussians = 0;  // Gaussians its per-Gaussian buffers hold: its slots (cuda/records.h Projected)
  int width = 0, height = 0;    // the viewport, pixels
  Pipeline pipeline = Pipeline::exact;
  std::uint64_t list_entries = 0;  // render-list entries the list buffers hold (one pass)
};

// Bytes a unit of each kind takes on the CUDA core (before GrowBuffer's slack).
struct BufferBytes {
  // splat 32, colour 16, depth 4, tile rectangle 8, tile count 4, tile mask 4, emission end 8,
  // big-Gaussian list 4.
  static constexpr std::uint64_t kPerGaussian = 80;
  // catgs: trail mean and motion 16, conic 16, covariance 16, trail mask 4, frustum cache 4, and
  // the cache selection's scratch (about 4).
  static constexpr std::uint64_t kPerGaussianCatgs = 60;
  // chunk entry count 4, chunk start 8, kept-chunk index 4 (and scan scratch).
  static constexpr std::uint64_t kPerChunk = 24;
  // tile range 8, tile order 4, split plan: tile plan 16, slice range and tile 16 for each of up
  // to two slices a tile on average (task_split.cu), saturation and done flags 8.
  static constexpr std::uint64_t kPerTile = 68;
  // RGB float 12, RGBA8 4, I420 planes 1.5 (rounded up to 2), the split tiles' partial colour
  // and transmittance (float4 a pixel of a slice; at most about one in two pixels sits in a split
  // tile's later slice) 8.
  static constexpr std::uint64_t kPerPixel = 26;
  // two key halves (8 each), two value halves (4 each) and the radix sort's scratch (about 4).
  static constexpr std::uint64_t kPerListEntry = 28;
  // Fixed: events, counters, CUB's small temporaries.
  static constexpr std::uint64_t kFixed = 1u << 20;
  // GrowBuffer's slack (cuda/tunables.h kGrowthFactor): a buffer holds up to 1.25 times its need.
  static constexpr double kGrowth = 1.25;
};

// Device bytes a session with buffers of `shape` takes at most, GrowBuffer's slack included.
std::uint64_t session_device_bytes(const SessionBufferShape& shape);

// A session's bytes before its renderer drew a frame: its buffers as the CUDA core first sizes
// them for a scene of `scene_gaussians` (fm::initial_slot_chunks: the whole of a small scene, an
// eighth of a large one) at width x height, its list buffers at `budget`'s one-pass maximum.
std::uint64_t first_session_device_bytes(std::uint64_t scene_gaussians, int width, int height, Pipeline pipeline,
                                         const RenderListBudget& budget);

// The render-list entries a session's list buffers are sized for at width x height: the
// list budget's one-pass maximum (RenderListBudget::max_entries with kPerListEntry), so a frame
// whose list is longer is drawn in passes within them and never grows them further.
std::uint64_t session_list_entries(const RenderListBudget& budget, int width, int height);

}  // namespace catgs
