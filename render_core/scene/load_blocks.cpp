// Parallel loading (load_blocks.h): std::thread workers pulling block indices from an atomic; the
// calling thread reports progress as blocks finish.
#include "scene/load_blocks.h"

#include <algorithm>
#include <atomic>
#include <condition_variable>
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
  const auto n = static_cast<int>(std::min<uint64_t>(static_cast<uint64_t>(load_threads(threads)), blocks));
  if (n <= 1) {  // serial: the calling thread alone, a tick after each block
    for (uint64_t b = 0; b < blocks; ++b) {
      block(b);
      if (tick) tick(b + 1);
    }
    return;
  }
  constexpr uint64_t kNone = std::numeric_limits<uint64_t>::max();
  std::atomic<uint64_t> next{0};
  std::atomic<bool> cancelled{false};
  std::mutex mutex;
  std::condition_variable changed;
  uint64_t finished = 0, failed_at = kNone;  // under mutex
  int running = n;
  std::exception_ptr error;  // of block failed_at

  auto work = [&] {
    for (;;) {
      const uint64_t b = next.fetch_add(1);
      if (b >= blocks || cancelled.load()) break;
      {
        const std::lock_guard<std::mutex> lock(mutex);
        if (b > failed_at) break;  // blocks are handed out in order: no lower one is left
      }
      std::exception_ptr e;
      try {
        block(b);
      } catch (...) {
        e = std::current_exception();
      }
      const std::lock_guard<std::mutex> lock(mutex);
      if (e && b < failed_at) {
        failed_at = b;
        error = e;
      }
      if (!e) ++finished;
      changed.notify_one();
      if (e) break;
    }
    const std::lock_guard<std::mutex> lock(mutex);
    --running;
    changed.notify_one();
  };
  std::vector<std::thread> workers;
  for (int t = 0; t < n; ++t) workers.emplace_back(work);

  // The calling thread: a tick for every block finished, in count order, until all stop.
  std::exception_ptr tick_error;
  uint64_t reported = 0;
  std::unique_lock<std::mutex> lock(mutex);
  for (;;) {
    changed.wait(lock, [&] { return running == 0 || finished > reported; });
    const uint64_t now = finished;
    const bool done = running == 0;
    if (tick && !tick_error) {
      lock.unlock();
      try {
        while (reported < now) tick(++reported);
      } catch (...) {
        tick_error = std::current_exception();
        cancelled = true;
      }
      lock.lock();
    }
    reported = std::max(reported, now);
    if (done && reported == finished) break;
  }
  lock.unlock();
  for (auto& w : workers) w.join();
  if (tick_error) std::rethrow_exception(tick_error);
  if (error) std::rethrow_exception(error);
}

}  // namespace catgs
