// alloc_bench GIB: how fast fresh memory becomes a zeroed float array (issue 74, the model's
// allocation: docs/history/scene_loading.md "The model's allocation"). Standalone, on purpose:
//   g++ -O2 -pthread scripts/alloc_bench.cpp -o .carry_srv/extra/alloc_bench
// then on the GPU machine (carry .carry_srv): .carry_srv/extra/alloc_bench 16
#include <sys/mman.h>
#include <unistd.h>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <thread>
#include <vector>
#include <algorithm>
#ifndef MADV_POPULATE_WRITE
#define MADV_POPULATE_WRITE 23
#endif
using clk = std::chrono::steady_clock;
double ms(clk::time_point a) { return std::chrono::duration<double, std::milli>(clk::now() - a).count(); }
int main(int argc, char** argv) {
  size_t gb = argc > 1 ? atol(argv[1]) : 8;
  size_t n = gb << 28;  // floats
  int T = std::thread::hardware_concurrency();
  {
    auto t = clk::now();
    std::vector<float> v(n);
    printf("plain resize %zu GiB: %.0f ms\n", gb, ms(t));
  }
  {
    auto t = clk::now();
    std::vector<float> v;
    v.reserve(n);
    uintptr_t page = 4096, b = ((uintptr_t)v.data() + page - 1) / page * page,
              e = ((uintptr_t)(v.data() + n)) / page * page;
    int rc = madvise((void*)b, e - b, MADV_POPULATE_WRITE);
    printf("populate (1 thread) rc=%d: %.0f ms\n", rc, ms(t));
    auto t2 = clk::now();
    v.resize(n);
    printf("then resize: %.0f ms\n", ms(t2));
  }
  {
    auto t = clk::now();
    std::vector<float> v;
    v.reserve(n);
    uintptr_t page = 4096, b = ((uintptr_t)v.data() + page - 1) / page * page,
              e = ((uintptr_t)(v.data() + n)) / page * page;
    std::vector<std::thread> th;
    size_t blk = (e - b) / T / page * page;
    for (int k = 0; k < T; ++k)
      th.emplace_back([=] {
        uintptr_t f = b + k * blk, to = k == T - 1 ? e : f + blk;
        madvise((void*)f, to - f, MADV_POPULATE_WRITE);
      });
    for (auto& x : th) x.join();
    printf("populate (%d threads): %.0f ms\n", T, ms(t));
    auto t2 = clk::now();
    v.resize(n);
    printf("then resize: %.0f ms\n", ms(t2));
  }
  {
    auto t = clk::now();
    float* p = (float*)malloc(n * 4);
    madvise(p, n * 4, MADV_HUGEPAGE);
    std::vector<std::thread> th;
    size_t blk = n / T;
    for (int k = 0; k < T; ++k) th.emplace_back([=] { memset(p + k * blk, 0, (k == T - 1 ? n - k * blk : blk) * 4); });
    for (auto& x : th) x.join();
    printf("malloc + hugepage + parallel memset: %.0f ms\n", ms(t));
    free(p);
  }
  {
    auto t = clk::now();
    float* p = (float*)malloc(n * 4);
    std::vector<std::thread> th;
    size_t blk = n / T;
    for (int k = 0; k < T; ++k) th.emplace_back([=] { memset(p + k * blk, 0, (k == T - 1 ? n - k * blk : blk) * 4); });
    for (auto& x : th) x.join();
    printf("malloc + parallel memset (first touch): %.0f ms\n", ms(t));
    free(p);
  }
}
