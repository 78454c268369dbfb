#include "proto/depth_grid_coding.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <zlib.h>

namespace catgs::server {

void pack_depth_grid(const DepthGrid& grid, pb::DepthGrid* out) {
  const auto surface = [](float z) { return std::isfinite(z) && z > 0.0f; };
  float w_max = 0.0f;
  for (const float z : grid.depth)
    if (surface(z)) w_max = std::max(w_max, 1.0f / z);
  std::string codes(grid.depth.size(), '\0');
  for (std::size_t i = 0; i < grid.depth.size(); ++i) {
    const float z = grid.depth[i];
    if (!surface(z) || !(w_max > 0.0f) || !std::isfinite(w_max)) continue;
    const float c = std::round(255.0f * (1.0f / z) / w_max);
    codes[i] = static_cast<char>(static_cast<unsigned char>(std::clamp(c, 1.0f, 255.0f)));
  }
  out->set_cols(static_cast<std::uint32_t>(grid.cols));
  out->set_rows(static_cast<std::uint32_t>(grid.rows));
  out->set_cell_px(static_cast<std::uint32_t>(grid.cell));
  out->set_inverse_depth_max(std::isfinite(w_max) ? w_max : 0.0f);
  // zlib (RFC 1950) at its best level: the grid is small, the level's time with it.
  uLongf size = compressBound(static_cast<uLong>(codes.size()));
  std::string deflated(size, '\0');
  if (compress2(reinterpret_cast<Bytef*>(deflated.data()), &size, reinterpret_cast<const Bytef*>(codes.data()),
                static_cast<uLong>(codes.size()), Z_BEST_COMPRESSION) != Z_OK)
    throw std::runtime_error("depth grid: zlib could not deflate " + std::to_string(codes.size()) + " codes");
  deflated.resize(size);
  out->set_inverse_depth(std::move(deflated));
}

DepthGrid unpack_depth_grid(const pb::DepthGrid& in) {
  constexpr std::uint32_t kMaxSide = 4097;
  if (in.cols() == 0 || in.rows() == 0 || in.cols() > kMaxSide || in.rows() > kMaxSide)
    throw std::invalid_argument("depth grid: shape " + std::to_string(in.cols()) + " x " + std::to_string(in.rows()) +
                                " is not 1..4097 a side");
  if (in.cell_px() == 0) throw std::invalid_argument("depth grid: cell_px is 0");
  const std::size_t n = static_cast<std::size_t>(in.cols()) * in.rows();
  // The codes inflated into exactly n bytes: a stream that is not zlib, is cut short, or holds
  // more or fewer codes is refused.
  std::string codes(n + 1, '\0');
  uLongf size = static_cast<uLongf>(codes.size());
  const int z = uncompress(reinterpret_cast<Bytef*>(codes.data()), &size,
                           reinterpret_cast<const Bytef*>(in.inverse_depth().data()),
                           static_cast<uLong>(in.inverse_depth().size()));
  if (z != Z_OK || size != n)
    throw std::invalid_argument("depth grid: " + std::to_string(in.inverse_depth().size()) +
                                " bytes are not a zlib stream of " + std::to_string(in.cols()) + " x " +
                                std::to_string(in.rows()) + " codes" +
                                (z == Z_OK ? " (it holds " + std::to_string(size) + ")" : ""));
  const float w_max = in.inverse_depth_max();
  DepthGrid g;
  g.cols = static_cast<int>(in.cols());
  g.rows = static_cast<int>(in.rows());
  g.cell = static_cast<int>(in.cell_px());
  g.depth.assign(n, INFINITY);
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<unsigned char>(codes[i]);
    if (c == 0) continue;
    if (!(std::isfinite(w_max) && w_max > 0.0f))
      throw std::invalid_argument("depth grid: inverse_depth_max " + std::to_string(w_max) +
                                  " is not finite and positive");
    g.depth[i] = 255.0f / (static_cast<float>(c) * w_max);
  }
  return g;
}

}  // namespace catgs::server
