// Parallel loading (load_blocks.h): std::thread workers pulling block indices from an atomic.
#include "scene/load_blocks.h"

#include <algorithm>
#include <atomic>
#include <exception>
#include <limits>
#include <mutex>
#include <thread>
#include <vector>

namespace catgs {

int load_threads(int requested) {
  if (requested > 0) return requested;
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

void run_blocks(uint64_t blocks, int threads, const std::function<void(uint64_t)>& block,
                const std::function<void(uint64_t)>& tick) {
  constexpr uint64_t kNone = std::numeric_limits<uint64_t>::max();
  std::atomic<uint64_t> next{0}, finished{0}, failed_at{kNone};
  std::atomic<bool> cancelled{false};
  std::mutex mutex;
  std::exception_ptr error;  // of block failed_at

  // Returns false when there is nothing left to do.
  auto one = [&]() {
    if (cancelled.load(std::memory_order_relaxed)) return false;
    const uint64_t b = next.fetch_add(1, std::memory_order_relaxed);
    if (b >= blocks || b > failed_at.load(std::memory_order_relaxed)) return false;
    try {
      block(b);
    } catch (...) {
      const std::lock_guard<std::mutex> lock(mutex);
      if (b < failed_at.load()) {
        failed_at.store(b);
        error = std::current_exception();
      }
      return false;
    }
    finished.fetch_add(1, std::memory_order_relaxed);
    return true;
  };

  const int n = static_cast<int>(std::min<uint64_t>(static_cast<uint64_t>(load_threads(threads)), blocks));
  std::vector<std::thread> workers;
  for (int t = 1; t < n; ++t)
    workers.emplace_back([&] {
      while (one()) {}
    });
  std::exception_ptr tick_error;
  try {
    while (one())
      if (tick) tick(finished.load(std::memory_order_relaxed));
  } catch (...) {
    tick_error = std::current_exception();
    cancelled = true;
  }
  for (auto& w : workers) w.join();
  if (tick_error) std::rethrow_exception(tick_error);
  if (error) std::rethrow_exception(error);
}

}  // namespace catgs
