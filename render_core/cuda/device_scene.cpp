// DeviceScene: one read-only copy of a GaussianModel in device memory, shared by renderers.
#include <algorithm>
#include <limits>
#include <string>

#include "base/cuda_check.h"
#include "cuda/cuda_renderer.h"
#include "forward_model/sh_storage.h"
#include "scene/load_blocks.h"

namespace catgs::cuda {

namespace {

template <typename T>
T* upload_array(const std::vector<T>& host, std::size_t* bytes_total, const char* what) {
  if (host.empty()) return nullptr;
  const std::size_t bytes = host.size() * sizeof(T);
  T* d = nullptr;
  try {
    CATGS_CUDA(cudaMalloc(&d, bytes));
  } catch (const CudaError& e) {
    throw CudaError(std::string("scene upload: ") + what + " needs " + std::to_string(bytes) + " bytes: " + e.what(),
                    e.code());
  }
  try {
    CATGS_CUDA(cudaMemcpy(d, host.data(), bytes, cudaMemcpyHostToDevice));
  } catch (...) {
    cudaFree(d);
    throw;
  }
  *bytes_total += bytes;
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
  // On a throw, the partially filled scene's destructor frees what was uploaded.
  s->means_ = upload_array(model.means, &s->bytes_, "means");
  s->log_scales_ = upload_array(model.log_scales, &s->bytes_, "log-scales");
  s->rotations_ = upload_array(model.rotations, &s->bytes_, "rotations");
  s->opacity_logits_ = upload_array(model.opacity_logits, &s->bytes_, "opacities");
  // SH in half precision (sh_storage.h): rounded here, on the host, by the same function the CPU
  // reference rounds with, so both cores read the same coefficients.
  // In parallel blocks: one thread rounds ~6 ns a coefficient, 1.1 s for the 7 M city's 190 M
  // (issue 37; docs/history/scene_loading.md).
  std::vector<uint16_t> sh_half(model.sh.size());
  constexpr std::size_t kBlock = 1 << 20;
  run_blocks((sh_half.size() + kBlock - 1) / kBlock, 0, [&](uint64_t b) {
    const std::size_t end = std::min(sh_half.size(), (b + 1) * kBlock);
    for (std::size_t k = b * kBlock; k < end; ++k) sh_half[k] = fm::half_bits(model.sh[k]);
  });
  s->sh_ = upload_array(sh_half, &s->bytes_, "SH coefficients");
  s->chunks_ = upload_array(chunk_bounds_of(model), &s->bytes_, "chunk bounds");
  fm::validate_lod(model.lod, n);
  s->lod_ = upload_array(model.lod, &s->bytes_, "LOD nodes");  // nullptr without LOD
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
  if (chunks_) cudaFree(chunks_);
  if (lod_) cudaFree(lod_);
  if (switched) (void)cudaSetDevice(previous);
}

}  // namespace catgs::cuda
