// Stage 1: per-Gaussian pre-processing (mirrors the CUDA preprocess kernel).
#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "cpu/cpu_renderer.h"
#include "cpu/host_buffer.h"
#include "forward_model/sh_storage.h"
#include "base/parallel_for.h"

namespace catgs::cpu {

void ProjectedGaussians::resize(std::size_t n) {
  // One growth of the host slot for them all (cpu/host_buffer.h): asked before any of them grows.
  constexpr std::uint64_t kBytes =
      3 * sizeof(glm::vec2) + 4 * sizeof(glm::vec3) + 5 * sizeof(float) + sizeof(fm::TileRect) + sizeof(std::uint32_t);
  if (must_grow(mean2d, n)) check_host_growth(n * kBytes, "pre-processed Gaussians");
  mean2d.resize(n);
  conic.resize(n);
  opacity.resize(n);
  depth.resize(n);
  q_max.resize(n);
  color.resize(n);
  tile_rect.resize(n);
  tiles_touched.resize(n);
  trail_mean0.resize(n);
  trail_motion.resize(n);
  trail_cov.resize(n);
  trail_conic.resize(n);
  q_trail.resize(n);
}

namespace {

// The tiles of `rect` the opacity-aware ellipse reaches (exact pipeline), less those whose
// entries occlusion culling hides (`hidden`: the frame's reprojected map, null for none; `depth`:
// the Gaussian's view depth).
uint32_t count_exact_tiles(const fm::TileRect& rect, glm::vec2 mean, glm::vec3 conic, float q_max, int width,
                           int height, const fm::OcclusionMap* hidden, float depth) {
  uint32_t n = 0;
  for (int ty = rect.y0; ty < rect.y1; ++ty)
    for (int tx = rect.x0; tx < rect.x1; ++tx)
      n += fm::ellipse_touches_tile(mean, conic, q_max, tx, ty, width, height) &&
                   !(hidden && fm::entry_hidden(*hidden, mean, conic, q_max, depth, tx, ty, width, height))
               ? 1u
               : 0u;
  return n;
}

}  // namespace

namespace {

// One view's constants for stage 1, worked out once per frame.
struct ViewPass {
  const Camera& camera;
  TileGrid grid;
  glm::vec2 tan_half_fov;
  glm::vec3 cam_pos;
  fm::View view;
  fm::LodCut lod;
  const fm::LodNode* lod_nodes;  // null: no LOD
  bool exact;
  fm::TileRect region;
  fm::OcclusionMap occlusion;
  ProjectedGaussians& out;

  ViewPass(const GaussianModel& model, const Camera& c, Pipeline pipeline, ProjectedGaussians& o, const fm::TileRect& r,
           float lod_error_px, const fm::OcclusionMap& occ)
      : camera(c),
        grid(TileGrid::of(c.width, c.height)),
        tan_half_fov(static_cast<float>(c.width) / (2.0f * c.fx), static_cast<float>(c.height) / (2.0f * c.fy)),
        cam_pos(c.position()),
        view(fm::view_of(c)),
        lod(fm::lod_cut(model.lod, view, lod_error_px)),
        lod_nodes(model.lod.empty() ? nullptr : model.lod.data()),
        exact(pipeline != Pipeline::vanilla),
        region(r),
        occlusion(occ),
        out(o) {}
};

// Gaussian i in view v: its projected features and tile count (0: not listed).
void preprocess_gaussian(const GaussianModel& model, const ViewPass& v, std::size_t i) {
  const Camera& camera = v.camera;
  ProjectedGaussians& out = v.out;
  out.tiles_touched[i] = 0;
  const glm::vec3 mean(model.means[3 * i], model.means[3 * i + 1], model.means[3 * i + 2]);
  const glm::vec3 p_cam = camera.R * mean + camera.t;
  if (!(p_cam.z > camera.near_plane) || p_cam.z > camera.far_plane) return;  // frustum (near/far)

  float opacity = fm::sigmoid(model.opacity_logits[i]);
  // alpha >= 1/255 only where q <= q_max; the rasterizer visits only those pixels (all
  // pipelines). exact also drops a Gaussian that can never reach 1/255.
  float q_max = fm::opacity_aware_qmax(opacity);
  if (v.exact && !(q_max > 0.0f)) return;
  const glm::vec2 mean2d(camera.fx * p_cam.x / p_cam.z + camera.cx - 0.5f,
                         camera.fy * p_cam.y / p_cam.z + camera.cy - 0.5f);

  const fm::Cov3 cov3 = fm::covariance_3d(
      {model.log_scales[3 * i], model.log_scales[3 * i + 1], model.log_scales[3 * i + 2]},
      {model.rotations[4 * i], model.rotations[4 * i + 1], model.rotations[4 * i + 2], model.rotations[4 * i + 3]});
  const glm::vec3 cov2 = fm::covariance_2d(cov3, camera.R, p_cam, camera.fx, camera.fy, v.tan_half_fov);
  glm::vec3 conic;
  if (!fm::conic_from_cov2d(cov2, &conic)) return;
  // A merged Gaussian keeps its coverage under the low-pass (fm::drawn_opacity): a lower peak,
  // and so a tighter q_max (fm::drawn_qmax, a bound of IEEE operations only, so both cores list
  // the same tiles). The culls above read the undrawn opacity's, which is no smaller.
  if (fm::lod_chunk_merged(v.lod_nodes, i / fm::kChunkSize)) {
    const float scale = fm::drawn_scale(cov2, true);
    opacity *= scale;
    q_max = fm::drawn_qmax(q_max, scale);
    if (v.exact && !(q_max > 0.0f)) return;
  }
  fm::TileRect rect;
  uint32_t touched;
  if (v.exact) {
    rect = fm::clip_tile_rect(fm::ellipse_tile_rect(mean2d, cov2, q_max, camera.width, camera.height), v.region);
    // Per-entry occlusion culling for a Gaussian of few tiles (fm::entry_hidden; as the CUDA core's
    // tile masks).
    const bool per_entry = v.occlusion.cells[0] != nullptr && fm::tile_count(rect) <= fm::kOcclusionEntryTiles;
    touched = fm::tile_count(rect) == 0 ? 0u
                                        : count_exact_tiles(rect, mean2d, conic, q_max, camera.width, camera.height,
                                                            per_entry ? &v.occlusion : nullptr, p_cam.z);
  } else {
    const float radius = fm::three_sigma_radius(cov2);
    rect = fm::clip_tile_rect(fm::square_tile_rect(mean2d, radius, v.grid.tiles_x, v.grid.tiles_y), v.region);
    touched = radius > 0.0f ? static_cast<uint32_t>(fm::tile_count(rect)) : 0u;
  }
  if (touched == 0) return;

  const int K = model.sh_coeffs();
  const glm::vec3 dir = glm::normalize(mean - v.cam_pos);
  out.mean2d[i] = mean2d;
  out.conic[i] = conic;
  out.opacity[i] = opacity;
  out.depth[i] = p_cam.z;
  out.q_max[i] = q_max;
  out.color[i] =
      fm::sh_to_color_from(model.sh_degree, fm::HalfRoundedSh{&model.sh[static_cast<std::size_t>(K) * 3 * i]}, dir);
  out.tile_rect[i] = rect;
  out.tiles_touched[i] = touched;
}

// Chunk c in view v, as the CUDA core takes a block per chunk: exact skips the chunks that cannot
// reach the image (the CUDA core's cull_chunks_kernel, which lists the chunks kept for its later
// stages). Their Gaussians get tiles_touched = 0 here; the CUDA core leaves them unwritten and
// reads them as 0 through its chunk totals (cuda/records.h listed_tiles); with occlusion culling,
// also the chunks the last frame's map hides whole (fm::chunk_hidden). Every pipeline skips the
// chunks outside the LOD cut (lod.h): another level draws them.
// Returns whether it was pre-processed.
bool preprocess_chunk(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks, const ViewPass& v,
                      std::size_t c) {
  const std::size_t begin = c * fm::kChunkSize, end = std::min(model.size(), begin + fm::kChunkSize);
  const bool outside =
      !v.lod.drawn(c) ||
      (v.exact && (fm::chunk_outside_view(chunks[c], v.view) || fm::chunk_hidden(v.occlusion, chunks[c], v.view)));
  for (std::size_t i = begin; i < end; ++i) {
    if (outside)
      v.out.tiles_touched[i] = 0;
    else
      preprocess_gaussian(model, v, i);
  }
  return !outside;
}

}  // namespace

void preprocess(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks, const Camera& camera,
                Pipeline pipeline, ProjectedGaussians& out, const fm::TileRect& region, float lod_error_px,
                const fm::OcclusionMap& occlusion) {
  if (chunks.size() != fm::chunk_count(model.size()))
    throw std::invalid_argument("preprocess: chunk bounds of another scene");
  out.resize(model.size());
  out.occlusion = occlusion;  // for emission's per-entry test
  const ViewPass v(model, camera, pipeline, out, region, lod_error_px, occlusion);
  std::atomic<std::size_t> kept{0};
  parallel_for(chunks.size(), 16, [&](std::size_t c) {
    if (preprocess_chunk(model, chunks, v, c)) kept.fetch_add(1, std::memory_order_relaxed);
  });
  out.chunks_kept = kept.load();
}

}  // namespace catgs::cpu
