// Parallel order statistics (order_statistics.h).
#include "process/order_statistics.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <string>

#include "scene/load_blocks.h"

namespace catgs::server {

namespace {

constexpr std::size_t kBlock = 1 << 18;  // values per parallel block
constexpr int kBuckets = 1 << 16;

// A key whose unsigned order is the floats' order (negative floats flipped whole, positive ones
// with their sign bit set), cut to its top 16 bits.
uint32_t bucket_of(float f) {
  uint32_t x;
  std::memcpy(&x, &f, sizeof x);
  x = (x & 0x80000000u) ? ~x : (x | 0x80000000u);
  return x >> 16;
}

uint64_t blocks_of(std::size_t n) { return (n + kBlock - 1) / kBlock; }

}  // namespace

float kth_smallest(const std::vector<float>& v, std::size_t k) {
  if (k >= v.size())
    throw std::invalid_argument("rank " + std::to_string(k) + " of " + std::to_string(v.size()) + " values");
  if (v.size() < 2 * kBlock) {  // small: not worth the threads
    std::vector<float> copy(v);
    std::nth_element(copy.begin(), copy.begin() + static_cast<std::ptrdiff_t>(k), copy.end());
    return copy[k];
  }
  std::vector<uint64_t> histogram(kBuckets, 0);
  std::mutex mutex;
  run_blocks(blocks_of(v.size()), 0, [&](uint64_t b) {
    std::vector<uint32_t> local(kBuckets, 0);
    const std::size_t end = std::min(v.size(), (b + 1) * kBlock);
    for (std::size_t i = b * kBlock; i < end; ++i) ++local[bucket_of(v[i])];
    const std::lock_guard<std::mutex> lock(mutex);
    for (int j = 0; j < kBuckets; ++j) histogram[j] += local[j];
  });
  uint32_t bucket = 0;
  std::size_t below = 0;
  while (below + histogram[bucket] <= k) below += histogram[bucket++];
  std::vector<float> in_bucket;
  in_bucket.reserve(histogram[bucket]);
  run_blocks(blocks_of(v.size()), 0, [&](uint64_t b) {
    std::vector<float> local;
    const std::size_t end = std::min(v.size(), (b + 1) * kBlock);
    for (std::size_t i = b * kBlock; i < end; ++i)
      if (bucket_of(v[i]) == bucket) local.push_back(v[i]);
    const std::lock_guard<std::mutex> lock(mutex);
    in_bucket.insert(in_bucket.end(), local.begin(), local.end());
  });
  const auto at = static_cast<std::ptrdiff_t>(k - below);
  std::nth_element(in_bucket.begin(), in_bucket.begin() + at, in_bucket.end());
  return in_bucket[static_cast<std::size_t>(at)];
}

void parallel_sort(std::vector<float>& v) {
  const uint64_t blocks = blocks_of(v.size());
  auto bound = [&](uint64_t b) { return v.begin() + static_cast<std::ptrdiff_t>(std::min(v.size(), b * kBlock)); };
  run_blocks(blocks, 0, [&](uint64_t b) { std::sort(bound(b), bound(b + 1)); });
  for (uint64_t width = 1; width < blocks; width *= 2)  // sorted runs of `width` blocks, merged in pairs
    run_blocks((blocks + 2 * width - 1) / (2 * width), 0, [&](uint64_t p) {
      const uint64_t first = p * 2 * width;
      std::inplace_merge(bound(first), bound(first + width), bound(first + 2 * width));
    });
}

}  // namespace catgs::server
