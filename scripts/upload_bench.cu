// upload_bench GIB: what bounds a scene's host -> device upload (issue 74: >= 10 GB/s asked;
// the server's StagedCopier, render_core/cuda/device_scene.cpp; RESULTS.md "Compact scene").
// Standalone, on purpose (the GPU machine has nvcc but not our dependencies):
//   nvcc -O2 -std=c++17 -Xcompiler -pthread scripts/upload_bench.cu -o /tmp/upload_bench
//   /tmp/upload_bench 8
// Rows, each over GIB GiB of a touched pageable source array (as the decoded model is):
//   bus:     cudaMemcpyAsync from one pinned buffer, PIECE bytes a copy, one stream (the DMA
//            engine alone: the ceiling of any staging);
//   fill:    the host copying the source into a pinned PIECE buffer with T threads (one call per
//            piece, threads spawned per call as scene/load_blocks.h run_blocks does);
//   staged:  both together, B buffers in turn (fill one while the others are on the bus), as
//            StagedCopier with B = 2, PIECE = 64 MiB;
//   pageable: cudaMemcpy straight from the pageable source (the driver's own staging);
//   register: cudaHostRegister of the source, then one copy from it (pinning in place).
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <thread>
#include <vector>

#define CK(x)                                                                             \
  do {                                                                                    \
    cudaError_t err_ = (x);                                                               \
    if (err_ != cudaSuccess) {                                                            \
      std::fprintf(stderr, "%s: %s (line %d)\n", #x, cudaGetErrorString(err_), __LINE__); \
      std::exit(1);                                                                       \
    }                                                                                     \
  } while (0)

using clk = std::chrono::steady_clock;
static double sec(clk::time_point a) { return std::chrono::duration<double>(clk::now() - a).count(); }

// Copies n bytes with T threads, each a contiguous share.
static void parallel_copy(char* to, const char* from, size_t n, int T) {
  std::vector<std::thread> ts;
  const size_t share = (n + T - 1) / T;
  for (int t = 0; t < T; ++t) {
    const size_t b = std::min(n, t * share), e = std::min(n, b + share);
    if (b < e) ts.emplace_back([=] { std::memcpy(to + b, from + b, e - b); });
  }
  for (auto& t : ts) t.join();
}

int main(int argc, char** argv) {
  const size_t gib = argc > 1 ? std::strtoul(argv[1], nullptr, 10) : 8;
  const size_t total = gib << 30;
  const int cores = static_cast<int>(std::thread::hardware_concurrency());
  std::vector<char> src(total);
  for (size_t i = 0; i < total; i += 4096) src[i] = static_cast<char>(i >> 12);  // touched
  char* dev = nullptr;
  CK(cudaMalloc(&dev, total));
  cudaStream_t stream;
  CK(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking));
  std::printf("source %zu GiB, %d cores\n| row | piece MiB | buffers | threads | GB/s |\n|---|---|---|---|---|\n", gib,
              cores);

  for (size_t piece_mib : {16, 64, 256}) {  // bus
    const size_t piece = piece_mib << 20;
    char* pinned = nullptr;
    CK(cudaMallocHost(&pinned, piece));
    std::memset(pinned, 1, piece);
    CK(cudaStreamSynchronize(stream));
    const auto t = clk::now();
    for (size_t off = 0; off < total; off += piece)
      CK(cudaMemcpyAsync(dev + off, pinned, std::min(piece, total - off), cudaMemcpyHostToDevice, stream));
    CK(cudaStreamSynchronize(stream));
    std::printf("| bus | %zu | 1 | - | %.2f |\n", piece_mib, total / sec(t) / 1e9);
    CK(cudaFreeHost(pinned));
  }

  const size_t piece = size_t{64} << 20;
  char* pinned[8];
  for (char*& p : pinned) {
    CK(cudaMallocHost(&p, piece));
    std::memset(p, 0, piece);
  }
  for (int T : {1, 4, cores}) {  // fill
    const auto t = clk::now();
    for (size_t off = 0; off < total; off += piece)
      parallel_copy(pinned[0], src.data() + off, std::min(piece, total - off), T);
    std::printf("| fill | 64 | 1 | %d | %.2f |\n", T, total / sec(t) / 1e9);
  }

  for (int B : {2, 4, 8}) {  // staged
    for (int T : {cores / 2, cores}) {
      std::vector<cudaEvent_t> left(B);
      for (auto& e : left) CK(cudaEventCreateWithFlags(&e, cudaEventDisableTiming));
      for (auto& e : left) CK(cudaEventRecord(e, stream));
      CK(cudaStreamSynchronize(stream));
      const auto t = clk::now();
      unsigned k = 0;
      for (size_t off = 0; off < total; off += piece, ++k) {
        const int b = static_cast<int>(k % B);
        const size_t count = std::min(piece, total - off);
        CK(cudaEventSynchronize(left[b]));
        parallel_copy(pinned[b], src.data() + off, count, T);
        CK(cudaMemcpyAsync(dev + off, pinned[b], count, cudaMemcpyHostToDevice, stream));
        CK(cudaEventRecord(left[b], stream));
      }
      CK(cudaStreamSynchronize(stream));
      std::printf("| staged | 64 | %d | %d | %.2f |\n", B, T, total / sec(t) / 1e9);
      for (auto& e : left) CK(cudaEventDestroy(e));
    }
  }

  {  // pageable
    const auto t = clk::now();
    CK(cudaMemcpy(dev, src.data(), total, cudaMemcpyHostToDevice));
    std::printf("| pageable | - | - | - | %.2f |\n", total / sec(t) / 1e9);
  }
  {  // register
    auto t = clk::now();
    CK(cudaHostRegister(src.data(), total, cudaHostRegisterDefault));
    const double reg = sec(t);
    t = clk::now();
    CK(cudaMemcpyAsync(dev, src.data(), total, cudaMemcpyHostToDevice, stream));
    CK(cudaStreamSynchronize(stream));
    const double copy = sec(t);
    CK(cudaHostUnregister(src.data()));
    std::printf("| register (%.3f s to pin) then copy | - | - | - | %.2f (with the pinning %.2f) |\n", reg,
                total / copy / 1e9, total / (reg + copy) / 1e9);
  }
  for (char* p : pinned) CK(cudaFreeHost(p));
  CK(cudaFree(dev));
  return 0;
}
