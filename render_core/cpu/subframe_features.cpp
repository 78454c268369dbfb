// catgs sub-frame: per-Gaussian features of the frustum cache at the frame's own pose (paper
// sec. 3.2), with the check that each ellipse still lies inside the trail the key frame listed.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>

#include "forward_model/trail.h"
#include "cpu/cpu_renderer.h"
#include "forward_model/sh_storage.h"
#include "base/parallel_for.h"

namespace catgs::cpu {

bool update_subframe_features(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks,
                              const Camera& camera, const std::vector<uint32_t>& cached, ProjectedGaussians& out,
                              bool key_colour, const fm::LodCut& key_cut) {
  const glm::vec2 tan_half_fov(static_cast<float>(camera.width) / (2.0f * camera.fx),
                               static_cast<float>(camera.height) / (2.0f * camera.fy));
  const glm::vec3 cam_pos = camera.position();
  const int K = model.sh_coeffs();
  const fm::LodNode* lod_nodes = model.lod.empty() ? nullptr : model.lod.data();
  std::atomic<bool> inside{true};
  parallel_for(cached.size(), 4096, [&](std::size_t c) {
    const uint32_t i = cached[c];
    const glm::vec3 mean(model.means[3 * i], model.means[3 * i + 1], model.means[3 * i + 2]);
    const glm::vec3 p = camera.R * mean + camera.t;
    out.opacity[i] = 0.0f;  // culled at this pose unless shown below
    if (!(p.z > camera.near_plane) || p.z > camera.far_plane) return;
    const fm::Cov3 cov3 = fm::covariance_3d(
        {model.log_scales[3 * i], model.log_scales[3 * i + 1], model.log_scales[3 * i + 2]},
        {model.rotations[4 * i], model.rotations[4 * i + 1], model.rotations[4 * i + 2], model.rotations[4 * i + 3]});
    const glm::vec3 cov2 = fm::covariance_2d(cov3, camera.R, p, camera.fx, camera.fy, tan_half_fov);
    glm::vec3 conic;
    if (!fm::conic_from_cov2d(cov2, &conic)) return;
    const glm::vec2 mean2d(camera.fx * p.x / p.z + camera.cx - 0.5f, camera.fy * p.y / p.z + camera.cy - 0.5f);
    // Reaching no pixel centre even at q_max + kExactQMargin (the widest level any raster test
    // uses): culled, no colour (as the CUDA kernel, which is bound by its reads).
    if (fm::tile_count(
            fm::ellipse_tile_rect(mean2d, cov2, out.q_max[i] + fm::kExactQMargin, camera.width, camera.height)) == 0)
      return;
    // Only an ellipse that reaches a pixel of this frame must lie inside its trail.
    const bool on_screen =
        fm::tile_count(fm::ellipse_tile_rect(mean2d, cov2, out.q_max[i], camera.width, camera.height)) > 0;
    if (on_screen &&
        !fm::trail_contains(out.trail_mean0[i], out.trail_motion[i], out.trail_cov[i], out.q_trail[i], mean2d, cov2,
                            out.q_max[i]) &&
        !fm::listed_tiles_cover(out.trail_mean0[i], out.trail_motion[i], out.trail_conic[i], out.q_trail[i], mean2d,
                                cov2, conic, out.q_max[i], camera.width, camera.height))
      inside.store(false, std::memory_order_relaxed);
    out.mean2d[i] = mean2d;
    out.conic[i] = conic;
    out.opacity[i] = fm::drawn_opacity(fm::sigmoid(model.opacity_logits[i]), cov2,
                                       fm::lod_chunk_merged(lod_nodes, i / fm::kChunkSize));
    if (key_colour) return;  // the key frame's, as listed (speculative_preprocess)
    out.color[i] =
        fm::sh_to_color_from(model.sh_degree, fm::HalfRoundedSh{&model.sh[static_cast<std::size_t>(K) * 3 * i]},
                             glm::normalize(mean - cam_pos));
  });
  if (!inside.load()) return false;
  return !unlisted_reach_image(model, chunks, camera, out, key_cut);
}

bool unlisted_reach_image(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks, const Camera& camera,
                          const ProjectedGaussians& projected, const fm::LodCut& key_cut) {
  const fm::View view = fm::view_of(camera);
  const std::size_t n = model.size();
  if (chunks.size() != fm::chunk_count(n))
    throw std::invalid_argument("unlisted_reach_image: chunk bounds of another scene");
  std::atomic<bool> reached{false};
  parallel_for(chunks.size(), 16, [&](std::size_t c) {
    if (reached.load(std::memory_order_relaxed) || !key_cut.drawn(c) || fm::chunk_outside_view(chunks[c], view)) return;
    for (std::size_t i = c * fm::kChunkSize; i < std::min(n, (c + 1) * fm::kChunkSize); ++i)
      if (projected.tiles_touched[i] == 0 &&
          fm::unlisted_reaches_image(&model.means[3 * i], &model.log_scales[3 * i], &model.rotations[4 * i],
                                     model.opacity_logits[i], view)) {
        reached.store(true, std::memory_order_relaxed);
        return;
      }
  });
  return reached.load();
}

}  // namespace catgs::cpu
