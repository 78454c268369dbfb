// CudaRenderer: runs the five stages on its own stream over reusable device buffers.
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "catgs/cpu_renderer.h"  // validate_camera
#include "cuda_check.h"
#include "stages.h"
#include "tunables.h"

namespace catgs::cuda {

namespace {

// A device allocation that only grows (by tune::kGrowthFactor), never per frame.
class GrowBuffer {
 public:
  GrowBuffer() = default;
  GrowBuffer(const GrowBuffer&) = delete;
  GrowBuffer& operator=(const GrowBuffer&) = delete;
  ~GrowBuffer() { if (ptr_) cudaFree(ptr_); }

  // Makes room for `bytes`; returns true when it had to reallocate (contents are then lost).
  // cudaFree waits for in-flight work on the device, so a buffer still read by an earlier frame
  // is never freed under it. Throws CudaError naming the size when device memory runs out.
  bool ensure(std::size_t bytes, const char* what, std::size_t* allocations) {
    if (bytes <= bytes_) return false;
    const auto want = static_cast<std::size_t>(static_cast<double>(bytes) * tune::kGrowthFactor) + 256;
    if (ptr_) CATGS_CUDA(cudaFree(ptr_));
    ptr_ = nullptr;
    bytes_ = 0;
    std::size_t got = want;
    if (cudaMalloc(&ptr_, want) != cudaSuccess) {
      // No room for the slack: take exactly what this frame needs (huge lists near the limit).
      (void)cudaGetLastError();
      ptr_ = nullptr;
      got = bytes;
      try {
        CATGS_CUDA(cudaMalloc(&ptr_, bytes));
      } catch (const CudaError& e) {
        ptr_ = nullptr;
        throw CudaError(std::string("CUDA renderer: ") + what + " buffer of " +
                            std::to_string(bytes) + " bytes: " + e.what(),
                        e.code());
      }
    }
    bytes_ = got;
    ++*allocations;
    return true;
  }
  template <typename T>
  T* as() const { return static_cast<T*>(ptr_); }
  std::size_t bytes() const { return bytes_; }

 private:
  void* ptr_ = nullptr;
  std::size_t bytes_ = 0;
};

enum Event { kStart, kPreprocessed, kKeysEmitted, kSorted, kRanged, kRasterized, kEventCount };

}  // namespace

struct CudaRenderer::State {
  cudaStream_t stream = nullptr;
  cudaEvent_t events[kEventCount] = {};
  cudaEvent_t counts_ready = nullptr;
  unsigned long long* host_counts = nullptr;  // pinned [2]: render list length, visible
  std::size_t allocations = 0, peak_bytes = 0;
  int syncs = 0;
  int width = 0, height = 0;

  // Per Gaussian.
  GrowBuffer mean2d, conic_opacity, color, depth, q_max, rect, tiles_touched, ends, scan_temp, big;
  // Per render-list entry (two halves each, for the radix sort's double buffer).
  GrowBuffer keys[2], values[2], sort_temp;
  // Per tile / pixel, and the small counters.
  GrowBuffer ranges, tile_scratch, tile_order, order_temp, rgb, rgba8, counters;
  const uint32_t* sorted_values = nullptr;

  std::size_t bytes() const {
    std::size_t b = 0;
    for (const GrowBuffer* g : {&mean2d, &conic_opacity, &color, &depth, &q_max, &rect,
                                &tiles_touched, &ends, &scan_temp, &big, &keys[0], &keys[1], &values[0],
                                &values[1], &sort_temp, &ranges, &tile_scratch, &tile_order, &order_temp, &rgb, &rgba8, &counters})
      b += g->bytes();
    return b;
  }
  void note_peak() { peak_bytes = std::max(peak_bytes, bytes()); }

  ~State() {
    if (host_counts) cudaFreeHost(host_counts);
    for (cudaEvent_t& e : events)
      if (e) cudaEventDestroy(e);
    if (counts_ready) cudaEventDestroy(counts_ready);
    if (stream) cudaStreamDestroy(stream);
  }
};

CudaRenderer::CudaRenderer(std::shared_ptr<const DeviceScene> scene, const RenderOptions& options)
    : scene_(std::move(scene)), state_(std::make_unique<State>()) {
  if (!scene_) throw std::invalid_argument("CudaRenderer: null scene");
  set_options(options);
  State& s = *state_;
  CATGS_CUDA(cudaStreamCreateWithFlags(&s.stream, cudaStreamNonBlocking));
  for (cudaEvent_t& e : s.events) CATGS_CUDA(cudaEventCreate(&e));
  // The readback event only orders the host; no timing needed.
  CATGS_CUDA(cudaEventCreateWithFlags(&s.counts_ready, cudaEventDisableTiming));
  CATGS_CUDA(cudaMallocHost(&s.host_counts, 2 * sizeof(unsigned long long)));
  // [0] visible, [1..2] readback (list length, visible), [3] big-Gaussian count (low 32 bits).
  s.counters.ensure(4 * sizeof(unsigned long long), "counters", &s.allocations);
}

CudaRenderer::~CudaRenderer() = default;

void CudaRenderer::set_options(const RenderOptions& options) {
  if (options.pipeline == Pipeline::catgs)
    throw std::invalid_argument("the catgs pipeline is not implemented in the CUDA renderer yet");
  options_ = options;
}

void CudaRenderer::set_scene(std::shared_ptr<const DeviceScene> scene) {
  if (!scene) throw std::invalid_argument("CudaRenderer::set_scene: null scene");
  // The previous frame may still read the old scene: finish it before letting go.
  CATGS_CUDA(cudaStreamSynchronize(state_->stream));
  scene_ = std::move(scene);
}

CUstream_st* CudaRenderer::stream() const { return state_->stream; }
std::size_t CudaRenderer::buffer_bytes() const { return state_->bytes(); }
std::size_t CudaRenderer::peak_buffer_bytes() const { return state_->peak_bytes; }
std::size_t CudaRenderer::allocation_count() const { return state_->allocations; }
int CudaRenderer::syncs_last_frame() const { return state_->syncs; }

DeviceFrame CudaRenderer::render_device(const Camera& camera) {
  cpu::validate_camera(camera);
  State& s = *state_;
  const DeviceScene& scene = *scene_;
  const bool exact = options_.pipeline != Pipeline::vanilla;
  const uint64_t n = scene.size();
  std::size_t* allocs = &s.allocations;

  stages::CameraParams cam{};
  cam.R = camera.R;
  cam.t = camera.t;
  cam.position = camera.position();
  cam.fx = camera.fx;
  cam.fy = camera.fy;
  cam.cx = camera.cx;
  cam.cy = camera.cy;
  cam.width = camera.width;
  cam.height = camera.height;
  cam.near_plane = camera.near_plane;
  cam.far_plane = camera.far_plane;
  cam.tan_half_fov = glm::vec2(static_cast<float>(camera.width) / (2.0f * camera.fx),
                               static_cast<float>(camera.height) / (2.0f * camera.fy));
  cam.tiles_x = (camera.width + tune::kTileSize - 1) / tune::kTileSize;
  cam.tiles_y = (camera.height + tune::kTileSize - 1) / tune::kTileSize;
  const auto tiles = static_cast<uint32_t>(cam.tiles_x * cam.tiles_y);
  const std::size_t pixels = static_cast<std::size_t>(camera.width) * camera.height;

  // Buffers sized by the scene and the image (grow only).
  s.mean2d.ensure(n * sizeof(float2), "2D means", allocs);
  s.conic_opacity.ensure(n * sizeof(float4), "conics", allocs);
  s.color.ensure(n * sizeof(float4), "colours", allocs);
  s.depth.ensure(n * sizeof(float), "depths", allocs);
  s.q_max.ensure(n * sizeof(float), "q_max", allocs);
  s.rect.ensure(n * sizeof(ushort4), "tile rectangles", allocs);
  s.tiles_touched.ensure(n * sizeof(uint32_t), "tile counts", allocs);
  s.ends.ensure(n * sizeof(uint64_t), "emission offsets", allocs);
  s.big.ensure(n * sizeof(uint32_t), "big-Gaussian list", allocs);
  s.scan_temp.ensure(stages::scan_temp_bytes(n), "scan scratch", allocs);
  s.ranges.ensure(tiles * sizeof(uint2), "tile ranges", allocs);
  if (tune::kHeavyTilesFirst) {
    s.tile_scratch.ensure(3 * static_cast<std::size_t>(tiles) * sizeof(uint32_t), "tile loads", allocs);
    s.tile_order.ensure(tiles * sizeof(uint32_t), "tile order", allocs);
    s.order_temp.ensure(stages::tile_order_temp_bytes(tiles), "tile order scratch", allocs);
  }
  s.rgb.ensure(pixels * 3 * sizeof(float), "RGB image", allocs);
  s.rgba8.ensure(pixels * sizeof(uint32_t), "RGBA8 image", allocs);

  const stages::SceneView sv{scene.means(), scene.log_scales(), scene.rotations(),
                             scene.opacity_logits(), scene.sh(), scene.sh_degree(), n};
  const stages::Projected proj{s.mean2d.as<float2>(),   s.conic_opacity.as<float4>(),
                               s.color.as<float4>(),    s.depth.as<float>(),
                               s.q_max.as<float>(),     s.rect.as<ushort4>(),
                               s.tiles_touched.as<uint32_t>()};
  auto* counters = s.counters.as<unsigned long long>();
  const stages::BigList big{s.big.as<uint32_t>(), reinterpret_cast<unsigned*>(counters + 3)};

  s.syncs = 0;
  CATGS_CUDA(cudaEventRecord(s.events[kStart], s.stream));
  CATGS_CUDA(cudaMemsetAsync(counters, 0, 4 * sizeof(unsigned long long), s.stream));
  stages::preprocess(sv, cam, exact, proj, counters, big, s.stream);
  CATGS_CUDA(cudaEventRecord(s.events[kPreprocessed], s.stream));

  stages::scan_tiles_touched(proj.tiles_touched, s.ends.as<uint64_t>(), n, s.scan_temp.as<void>(),
                             s.scan_temp.bytes(), counters, counters + 1, s.stream);
  // The one host-device sync of a frame: CUB's radix sort takes the list length from the host,
  // and the list buffers may need to grow before emission writes into them.
  CATGS_CUDA(cudaMemcpyAsync(s.host_counts, counters + 1, 2 * sizeof(unsigned long long),
                             cudaMemcpyDeviceToHost, s.stream));
  CATGS_CUDA(cudaEventRecord(s.counts_ready, s.stream));
  CATGS_CUDA(cudaEventSynchronize(s.counts_ready));
  ++s.syncs;
  const uint64_t entries = s.host_counts[0];
  const uint64_t visible = s.host_counts[1];
  if (entries > std::numeric_limits<uint32_t>::max())
    throw std::length_error("CUDA renderer: render list of " + std::to_string(entries) +
                            " entries exceeds 2^32 - 1 (32-bit tile ranges); lower the resolution "
                            "or split the scene");

  const int key_bits = tune::kDepthBits + tune::tile_key_bits(tiles);
  for (int h = 0; h < 2; ++h) {
    s.keys[h].ensure(entries * sizeof(uint64_t), "render-list keys", allocs);
    s.values[h].ensure(entries * sizeof(uint32_t), "render-list values", allocs);
  }
  s.sort_temp.ensure(stages::sort_temp_bytes(entries, key_bits), "sort scratch", allocs);
  s.note_peak();

  uint64_t* keys[2] = {s.keys[0].as<uint64_t>(), s.keys[1].as<uint64_t>()};
  uint32_t* values[2] = {s.values[0].as<uint32_t>(), s.values[1].as<uint32_t>()};
  stages::emit_keys(proj, s.ends.as<uint64_t>(), n, cam, exact, big, keys[0], values[0], s.stream);
  CATGS_CUDA(cudaEventRecord(s.events[kKeysEmitted], s.stream));

  const int half = stages::sort_pairs(keys, values, entries, key_bits, s.sort_temp.as<void>(),
                                      s.sort_temp.bytes(), s.stream);
  CATGS_CUDA(cudaEventRecord(s.events[kSorted], s.stream));

  stages::tile_ranges(keys[half], entries, tiles, s.ranges.as<uint2>(), s.stream);
  const uint32_t* order = nullptr;
  if (tune::kHeavyTilesFirst) {
    stages::order_tiles(s.ranges.as<uint2>(), tiles, entries, s.tile_scratch.as<uint32_t>(),
                        s.tile_order.as<uint32_t>(), s.order_temp.as<void>(), s.order_temp.bytes(),
                        s.stream);
    order = s.tile_order.as<uint32_t>();
  }
  CATGS_CUDA(cudaEventRecord(s.events[kRanged], s.stream));

  const float3 bg = make_float3(options_.background.x, options_.background.y, options_.background.z);
  stages::rasterize(s.ranges.as<uint2>(), order, values[half], proj, cam, exact && warp_culling_, bg,
                    s.rgb.as<float>(), s.rgba8.as<uint32_t>(), s.stream);
  CATGS_CUDA(cudaEventRecord(s.events[kRasterized], s.stream));

  s.width = camera.width;
  s.height = camera.height;
  stats_ = {};
  stats_.visible = static_cast<std::size_t>(visible);
  stats_.render_list_length = static_cast<std::size_t>(entries);
  stats_ready_ = false;
  return {camera.width, camera.height, s.rgb.as<float>(), s.rgba8.as<uint32_t>(), s.stream};
}

const FrameStats& CudaRenderer::last_stats() const {
  if (stats_ready_) return stats_;
  const State& s = *state_;
  CATGS_CUDA(cudaEventSynchronize(s.events[kRasterized]));
  auto ms = [&](Event a, Event b) {
    float t = 0.0f;
    CATGS_CUDA(cudaEventElapsedTime(&t, s.events[a], s.events[b]));
    return static_cast<double>(t);
  };
  stats_.preprocess_ms = ms(kStart, kPreprocessed);
  stats_.keys_ms = ms(kPreprocessed, kKeysEmitted);
  stats_.sort_ms = ms(kKeysEmitted, kSorted);
  stats_.ranges_ms = ms(kSorted, kRanged);
  stats_.rasterize_ms = ms(kRanged, kRasterized);
  stats_.total_ms = ms(kStart, kRasterized);
  stats_ready_ = true;
  return stats_;
}

std::size_t CudaRenderer::heaviest_tile_entries() const {
  const State& s = *state_;
  if (!tune::kHeavyTilesFirst || s.width == 0) return 0;
  CATGS_CUDA(cudaEventSynchronize(s.events[kRasterized]));
  const uint32_t tiles = static_cast<uint32_t>(((s.width + tune::kTileSize - 1) / tune::kTileSize) *
                                               ((s.height + tune::kTileSize - 1) / tune::kTileSize));
  uint32_t heaviest = 0;  // order_tiles sorted the loads (descending) into scratch[tiles ..]
  CATGS_CUDA(cudaMemcpy(&heaviest, s.tile_scratch.as<uint32_t>() + tiles, sizeof heaviest,
                        cudaMemcpyDeviceToHost));
  return heaviest;
}

void CudaRenderer::render(const Camera& camera, Image& out) {
  const DeviceFrame f = render_device(camera);
  const std::size_t pixels = static_cast<std::size_t>(f.width) * f.height;
  out.width = f.width;
  out.height = f.height;
  out.rgb.resize(pixels * 3);
  out.rgba8.resize(pixels * 4);
  // Packed R | G << 8 | B << 16 | A << 24 is bytes R, G, B, A in memory (little endian).
  CATGS_CUDA(cudaMemcpyAsync(out.rgb.data(), f.rgb, pixels * 3 * sizeof(float),
                             cudaMemcpyDeviceToHost, state_->stream));
  CATGS_CUDA(cudaMemcpyAsync(out.rgba8.data(), f.rgba8, pixels * 4, cudaMemcpyDeviceToHost,
                             state_->stream));
  CATGS_CUDA(cudaStreamSynchronize(state_->stream));
}

std::unique_ptr<Renderer> make_cuda_renderer(std::shared_ptr<const GaussianModel> model,
                                             const RenderOptions& options) {
  if (!model) throw std::invalid_argument("make_cuda_renderer: null model");
  return std::make_unique<CudaRenderer>(DeviceScene::upload(*model), options);
}

}  // namespace catgs::cuda
