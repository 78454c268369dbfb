// DeviceScene: one read-only copy of a GaussianModel in device memory, shared by renderers.
#include <algorithm>
#include <chrono>
#include <cstring>
#include <limits>
#include <string>

#include "base/cuda_check.h"
#include "cuda/cuda_renderer.h"
#include "cuda/renderer_state.h"
#include "forward_model/sh_storage.h"
#include "scene/compact_file.h"
#include "scene/load_blocks.h"

namespace catgs::cuda {

namespace {

// Host -> device copies through two pinned staging buffers (issue 74). A cudaMemcpy from pageable
// memory goes through the driver's own small staging area, a fraction of the bus's speed (the
// rates before and after: RESULTS.md "Level of detail"). From pinned memory the copy is DMA, and the host fills one
// buffer (in parallel blocks: one thread's memcpy is slower than the bus) while the other is on
// the bus. Where the host refuses pinned memory, the same copies go from a pageable buffer.
class StagedCopier {
 public:
  static constexpr std::size_t kStageBytes = std::size_t{64} << 20;

  StagedCopier() {
    try {
      for (PinnedBuffer& b : pinned_) b.ensure(kStageBytes, "scene upload staging");
    } catch (const OutOfMemoryError&) {
      pageable_.resize(kStageBytes);
      return;
    }
    CATGS_CUDA(cudaStreamCreateWithFlags(&stream_, cudaStreamNonBlocking));
    for (cudaEvent_t& e : left_) CATGS_CUDA(cudaEventCreateWithFlags(&e, cudaEventDisableTiming));
  }
  ~StagedCopier() {
    // Nothing may still be copying out of the buffers (or into device memory a failed upload
    // frees) once this is gone; errors here (a dead context) are ignored.
    if (stream_) (void)cudaStreamSynchronize(stream_);
    for (cudaEvent_t e : left_)
      if (e) (void)cudaEventDestroy(e);
    if (stream_) (void)cudaStreamDestroy(stream_);
  }
  StagedCopier(const StagedCopier&) = delete;
  StagedCopier& operator=(const StagedCopier&) = delete;

  // Copies `bytes` to device memory at `dst`; fill(stage, offset, count) writes the source's bytes
  // [offset, offset + count) into `stage` (count <= kStageBytes, offsets multiples of it).
  template <typename Fill>
  void copy(void* dst, std::size_t bytes, const Fill& fill) {
    for (std::size_t offset = 0; offset < bytes; offset += kStageBytes) {
      const std::size_t count = std::min(kStageBytes, bytes - offset);
      char* to = static_cast<char*>(dst) + offset;
      if (!stream_) {
        fill(pageable_.data(), offset, count);
        CATGS_CUDA(cudaMemcpy(to, pageable_.data(), count, cudaMemcpyHostToDevice));
        continue;
      }
      const int k = next_++ & 1;
      CATGS_CUDA(cudaEventSynchronize(left_[k]));  // this buffer's previous copy has left it
      fill(reinterpret_cast<char*>(pinned_[k].data()), offset, count);
      CATGS_CUDA(cudaMemcpyAsync(to, pinned_[k].data(), count, cudaMemcpyHostToDevice, stream_));
      CATGS_CUDA(cudaEventRecord(left_[k], stream_));
    }
  }
  // Every copy has arrived.
  void finish() {
    if (stream_) CATGS_CUDA(cudaStreamSynchronize(stream_));
  }

 private:
  PinnedBuffer pinned_[2];
  std::vector<char> pageable_;
  cudaStream_t stream_ = nullptr;
  cudaEvent_t left_[2] = {nullptr, nullptr};
  unsigned next_ = 0;
};

// Runs rows(begin, end) over [0, count) in parallel blocks (scene/load_blocks.h).
template <typename Rows>
void parallel_rows(std::size_t count, const Rows& rows) {
  constexpr std::size_t kBlock = std::size_t{1} << 20;
  run_blocks((count + kBlock - 1) / kBlock, 0, [&](uint64_t b) {
    rows(static_cast<std::size_t>(b) * kBlock, std::min(count, static_cast<std::size_t>(b + 1) * kBlock));
  });
}

// cudaMalloc with the array's name in the error.
template <typename T>
T* device_array(std::size_t count, const char* what) {
  const std::size_t bytes = count * sizeof(T);
  T* d = nullptr;
  try {
    CATGS_CUDA(cudaMalloc(&d, bytes));
  } catch (const CudaError& e) {
    throw CudaError(std::string("scene upload: ") + what + " needs " + std::to_string(bytes) + " bytes: " + e.what(),
                    e.code());
  }
  return d;
}

// `host` into new device memory through `copier` (the bytes counted in `bytes_total`);
// nullptr for an empty array. The caller owns the pointer from its return, copied or not.
template <typename T, typename A>
T* upload_array(StagedCopier& copier, const std::vector<T, A>& host, std::size_t* bytes_total, const char* what) {
  if (host.empty()) return nullptr;
  T* d = device_array<T>(host.size(), what);
  *bytes_total += host.size() * sizeof(T);
  const char* src = reinterpret_cast<const char*>(host.data());
  copier.copy(d, host.size() * sizeof(T), [src](char* stage, std::size_t offset, std::size_t count) {
    parallel_rows(count, [&](std::size_t b, std::size_t e) { std::memcpy(stage + b, src + offset + b, e - b); });
  });
  return d;
}

}  // namespace

std::shared_ptr<const DeviceScene> DeviceScene::upload(const GaussianModel& model, int device) {
  const std::size_t n = model.size();
  if (n > std::numeric_limits<uint32_t>::max())
    throw std::length_error("scene '" + model.name + "' has " + std::to_string(n) +
                            " Gaussians; the CUDA core indexes them with 32 bits (max 2^32 - 1)");
  const std::size_t K = static_cast<std::size_t>(model.sh_coeffs());
  if (model.sh_degree < 0 || model.sh_degree > kMaxShDegree || model.means.size() != 3 * n ||
      model.log_scales.size() != 3 * n || model.rotations.size() != 4 * n || model.sh.size() != n * K * 3)
    throw std::invalid_argument("scene '" + model.name + "': array sizes disagree with " + std::to_string(n) +
                                " Gaussians");
  const DeviceGuard on(device);
  std::shared_ptr<DeviceScene> s(new DeviceScene());
  s->device_ = device;
  s->name_ = model.name;
  s->n_ = n;
  s->sh_degree_ = model.sh_degree;
  // On a throw, the copier waits for its copies, then the partially filled scene's destructor
  // frees what was uploaded.
  using Clock = std::chrono::steady_clock;
  const auto since = [](Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
  };
  auto t = Clock::now();
  const bool compact = compact_codes_match(model);  // the codes, where they still decode to the arrays
  s->upload_times_.check_ms = since(t);
  t = Clock::now();
  const std::vector<fm::ChunkBounds> chunks = chunk_bounds_of(model);
  s->upload_times_.bounds_ms = since(t);
  t = Clock::now();
  StagedCopier copier;
  s->means_ = upload_array(copier, model.means, &s->bytes_, "means");
  if (compact) {
    const CompactCodes& c = *model.codes;
    s->rotation_codes_ = upload_array(copier, c.rotation, &s->bytes_, "rotation codes");
    s->scale_codes_ = upload_array(copier, c.scale, &s->bytes_, "log-scale codes");
    s->colour_codes_ = upload_array(copier, c.colour, &s->bytes_, "colour codes");
    s->sh_codes_ = upload_array(copier, c.sh, &s->bytes_, "SH codes");
    if (!s->sh_codes_) s->sh_codes_ = device_array<uint8_t>(1, "SH codes");  // degree 0: non-null all the same
    s->sh_code_bytes_ = c.sh_bytes;
    s->chunk_ranges_ = upload_array(copier, c.ranges, &s->bytes_, "chunk ranges");
    const std::vector<float> lut(c.opacity_logit, c.opacity_logit + 256);
    s->opacity_lut_ = upload_array(copier, lut, &s->bytes_, "opacity table");
  }
  if (!compact) s->log_scales_ = upload_array(copier, model.log_scales, &s->bytes_, "log-scales");
  if (!compact) s->rotations_ = upload_array(copier, model.rotations, &s->bytes_, "rotations");
  if (!compact) s->opacity_logits_ = upload_array(copier, model.opacity_logits, &s->bytes_, "opacities");
  // SH in half precision (sh_storage.h): rounded on the host, by the same function the CPU
  // reference rounds with, so both cores read the same coefficients; straight into the staging
  // buffer, in parallel blocks (one thread rounds ~6 ns a coefficient, 1.1 s for the 7 M city's
  // 190 M: issue 37, docs/history/scene_loading.md).
  if (!compact && !model.sh.empty()) {
    s->sh_ = device_array<uint16_t>(model.sh.size(), "SH coefficients");
    s->bytes_ += model.sh.size() * sizeof(uint16_t);
    const float* sh = model.sh.data();
    copier.copy(s->sh_, model.sh.size() * sizeof(uint16_t), [sh](char* stage, std::size_t offset, std::size_t count) {
      uint16_t* to = reinterpret_cast<uint16_t*>(stage);
      const float* from = sh + offset / sizeof(uint16_t);
      parallel_rows(count / sizeof(uint16_t), [&](std::size_t b, std::size_t e) {
        for (std::size_t k = b; k < e; ++k) to[k] = fm::half_bits(from[k]);
      });
    });
  }
  s->chunks_ = upload_array(copier, chunks, &s->bytes_, "chunk bounds");
  fm::validate_lod(model.lod, n);
  s->lod_ = upload_array(copier, model.lod, &s->bytes_, "LOD nodes");  // nullptr without LOD
  copier.finish();
  s->upload_times_.copy_ms = since(t);
  s->upload_times_.copied_bytes = s->bytes_;
  return s;
}

DeviceScene::~DeviceScene() {
  // Destructors must not throw: errors here (a dead context at exit) are ignored.
  int previous = 0;
  const bool switched =
      cudaGetDevice(&previous) == cudaSuccess && previous != device_ && cudaSetDevice(device_) == cudaSuccess;
  for (float* p : {means_, log_scales_, rotations_, opacity_logits_})
    if (p) cudaFree(p);
  if (sh_) cudaFree(sh_);
  for (void* p :
       {static_cast<void*>(rotation_codes_), static_cast<void*>(scale_codes_), static_cast<void*>(colour_codes_),
        static_cast<void*>(sh_codes_), static_cast<void*>(chunk_ranges_), static_cast<void*>(opacity_lut_)})
    if (p) cudaFree(p);
  if (chunks_) cudaFree(chunks_);
  if (lod_) cudaFree(lod_);
  if (switched) (void)cudaSetDevice(previous);
}

}  // namespace catgs::cuda
