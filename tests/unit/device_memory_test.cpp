// renderer/device_memory.h: the accounting the server admits sessions by (issue 61). The GPU test
// DeviceMemory.EstimateBoundsTheBuffers holds it to a real CUDA renderer's buffers; here, what it
// must do whatever the byte counts: follow each thing a session's buffers are sized by.
#include <gtest/gtest.h>

#include "renderer/device_memory.h"

namespace catgs {
namespace {

SessionBufferShape shape(std::uint64_t gaussians, int w, int h, std::uint64_t entries) {
  SessionBufferShape s;
  s.gaussians = gaussians;
  s.width = w;
  s.height = h;
  s.list_entries = entries;
  return s;
}

TEST(DeviceMemory, SessionBytesFollowGaussiansPixelsAndList) {
  const std::uint64_t base = session_device_bytes(shape(1'000'000, 1280, 720, 10'000'000));
  // Each term by its own bytes a unit, with GrowBuffer's slack.
  const double g = BufferBytes::kGrowth;
  EXPECT_NEAR(static_cast<double>(session_device_bytes(shape(2'000'000, 1280, 720, 10'000'000)) - base),
              1e6 * (BufferBytes::kPerGaussian + BufferBytes::kPerChunk / 256.0) * g, 1e5);
  EXPECT_NEAR(static_cast<double>(session_device_bytes(shape(1'000'000, 1280, 720, 20'000'000)) - base),
              1e7 * BufferBytes::kPerListEntry * g, 1e3);
  EXPECT_GT(session_device_bytes(shape(1'000'000, 1920, 1080, 10'000'000)), base);
  SessionBufferShape catgs = shape(1'000'000, 1280, 720, 10'000'000);
  catgs.pipeline = Pipeline::catgs;
  EXPECT_NEAR(static_cast<double>(session_device_bytes(catgs) - base), 1e6 * BufferBytes::kPerGaussianCatgs * g, 1e3);
  EXPECT_EQ(session_device_bytes(shape(0, 0, 0, 0)), BufferBytes::kFixed);
}

TEST(DeviceMemory, ListEntriesFollowTheBudget) {
  RenderListBudget budget;
  budget.max_bytes = 512ull << 20;
  // 1280x720: 80 x 45 tiles x 16384 = 59 M entries, cut to 512 MiB / 28 bytes.
  EXPECT_EQ(session_list_entries(budget, 1280, 720), (512ull << 20) / BufferBytes::kPerListEntry);
  budget.max_bytes = 4ull << 30;
  EXPECT_EQ(session_list_entries(budget, 1280, 720), 80ull * 45 * 16384);
  EXPECT_EQ(session_list_entries(budget, 64, 64), 1ull << 24);  // the floor: a whole scene in a thumbnail
}

}  // namespace
}  // namespace catgs
