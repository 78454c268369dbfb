#include "renderer/device_memory.h"

#include <algorithm>

#include "forward_model/chunk_bounds.h"
#include "forward_model/lod.h"

namespace catgs {

std::uint64_t scene_device_bytes(const GaussianModel& model) {
  const std::uint64_t n = model.size();
  const auto sh_halves = n * static_cast<std::uint64_t>(model.sh_coeffs()) * 3;
  return n * (3 + 3 + 4 + 1) * sizeof(float) + sh_halves * sizeof(std::uint16_t) +
         fm::chunk_count(n) * sizeof(fm::ChunkBounds) + model.lod.size() * sizeof(fm::LodNode);
}

std::uint64_t session_list_entries(const RenderListBudget& budget, int width, int height) {
  return budget.max_entries(width, height, BufferBytes::kPerListEntry);
}

std::uint64_t session_device_bytes(const SessionBufferShape& s) {
  using B = BufferBytes;
  const std::uint64_t per_gaussian = B::kPerGaussian + (s.pipeline == Pipeline::catgs ? B::kPerGaussianCatgs : 0);
  const auto tiles = static_cast<std::uint64_t>((std::max(s.width, 0) + 15) / 16) *
                     static_cast<std::uint64_t>((std::max(s.height, 0) + 15) / 16);
  const auto pixels =
      static_cast<std::uint64_t>(std::max(s.width, 0)) * static_cast<std::uint64_t>(std::max(s.height, 0));
  const double need =
      static_cast<double>(per_gaussian * s.gaussians + B::kPerChunk * fm::chunk_count(s.gaussians) +
                          B::kPerTile * tiles + B::kPerPixel * pixels + B::kPerListEntry * s.list_entries);
  return static_cast<std::uint64_t>(need * B::kGrowth) + B::kFixed;
}

std::uint64_t first_session_device_bytes(std::uint64_t scene_gaussians, int width, int height, Pipeline pipeline,
                                         const RenderListBudget& budget) {
  SessionBufferShape shape;
  shape.gaussians = fm::initial_slot_chunks(fm::chunk_count(scene_gaussians)) * fm::kChunkSize;
  shape.width = width;
  shape.height = height;
  shape.pipeline = pipeline;
  shape.list_entries = session_list_entries(budget, width, height);
  return session_device_bytes(shape);
}

}  // namespace catgs
