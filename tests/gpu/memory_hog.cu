// catgs-memory-hog GIB [SECONDS]: another process that holds GIB GiB of the GPU's memory (issue
// 73: a second server pod, a training job), allocated and written so the driver counts it, then
// sleeps SECONDS (default: until killed). Prints "holding N GiB, F GiB free" once it holds them.
// scripts/gpu_server_run.sh hogramp runs the server beside it.
#include <cuda_runtime.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <vector>

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: catgs-memory-hog GIB [SECONDS]\n");
    return 2;
  }
  const double gib = std::atof(argv[1]);
  const double seconds = argc > 2 ? std::atof(argv[2]) : 1e9;
  // In 1 GiB pieces (the last one smaller), each written once.
  std::vector<void*> pieces;
  for (double left = gib; left > 0; left -= 1.0) {
    const auto bytes = static_cast<std::size_t>((left >= 1.0 ? 1.0 : left) * (1ull << 30));
    void* p = nullptr;
    if (cudaMalloc(&p, bytes) != cudaSuccess || cudaMemset(p, 0xa5, bytes) != cudaSuccess) {
      std::fprintf(stderr, "catgs-memory-hog: only %zu GiB could be held\n", pieces.size());
      return 1;
    }
    pieces.push_back(p);
  }
  cudaDeviceSynchronize();
  std::size_t free_bytes = 0, total = 0;
  cudaMemGetInfo(&free_bytes, &total);
  std::printf("holding %.1f GiB, %.1f GiB free of %.1f GiB\n", gib, free_bytes / 1073741824.0, total / 1073741824.0);
  std::fflush(stdout);
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  return 0;
}
