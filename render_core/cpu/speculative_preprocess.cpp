// catgs key frame, stage 1: pre-processing over the speculation window (paper sec. 3.1). Mirrors
// preprocess.cpp, projecting each Gaussian at every camera of the predicted path and testing
// tiles against its trail instead of its ellipse.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "forward_model/chunk_bounds.h"
#include "forward_model/trail.h"
#include "cpu/cpu_renderer.h"
#include "forward_model/sh_storage.h"
#include "base/parallel_for.h"

namespace catgs::cpu {

namespace {

struct CameraTerms {
  fm::View view;
  glm::vec3 position;
};

}  // namespace

float max_screen_motion(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks, const Camera& a,
                        const Camera& b, float min_depth, float lod_error_px) {
  const std::size_t n = model.size();
  if (chunks.size() != fm::chunk_count(n))
    throw std::invalid_argument("max_screen_motion: chunk bounds of another scene");
  const fm::View va = fm::view_of(a);
  const fm::LodCut lod = fm::lod_cut(model.lod, va, lod_error_px);
  std::vector<float> per_chunk(chunks.size(), 0.0f);
  parallel_for(chunks.size(), 16, [&](std::size_t c) {
    // A chunk none of whose means can count is skipped whole, as the CUDA stage does
    // (fm::chunk_means_off_image: on a scene of many copies most chunks lie off the key image).
    if (!lod.drawn(c) || fm::chunk_means_off_image(chunks[c], va, min_depth)) return;
    float m = 0.0f;
    for (std::size_t i = c * fm::kChunkSize; i < std::min(n, (c + 1) * fm::kChunkSize); ++i) {
      const glm::vec3 x(model.means[3 * i], model.means[3 * i + 1], model.means[3 * i + 2]);
      const glm::vec3 pa = a.R * x + a.t, pb = b.R * x + b.t;
      if (!(pa.z > min_depth) || !(pb.z > a.near_plane)) continue;
      const glm::vec2 ua(a.fx * pa.x / pa.z + a.cx, a.fy * pa.y / pa.z + a.cy);
      if (ua.x < 0 || ua.y < 0 || ua.x > static_cast<float>(a.width) || ua.y > static_cast<float>(a.height)) continue;
      const glm::vec2 ub(b.fx * pb.x / pb.z + b.cx, b.fy * pb.y / pb.z + b.cy);
      m = std::max(m, glm::length(ub - ua));
    }
    per_chunk[c] = m;
  });
  float m = 0.0f;
  for (float v : per_chunk) m = std::max(m, v);
  return m;
}

void speculative_preprocess(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks,
                            const std::vector<Camera>& path, const TrailWidening& widening, ProjectedGaussians& out,
                            float lod_error_px) {
  if (path.empty() || path.size() > static_cast<std::size_t>(kMaxPathCameras))
    throw std::invalid_argument("speculation path must hold 1.." + std::to_string(kMaxPathCameras) + " cameras");
  const std::size_t n = model.size();
  out.resize(n);
  const Camera& key = path.front();
  const int K = model.sh_coeffs();
  std::vector<CameraTerms> terms(path.size());
  for (std::size_t k = 0; k < path.size(); ++k) terms[k] = {fm::view_of(path[k]), path[k].position()};
  if (chunks.size() != fm::chunk_count(n))
    throw std::invalid_argument("speculative_preprocess: chunk bounds of another scene");

  const fm::LodNode* lod_nodes = model.lod.empty() ? nullptr : model.lod.data();
  auto gaussian = [&](std::size_t i) {
    out.tiles_touched[i] = 0;
    const float opacity = fm::sigmoid(model.opacity_logits[i]);
    const float q_max = fm::opacity_aware_qmax(opacity);
    if (!(q_max > 0.0f)) return;
    const glm::vec3 mean(model.means[3 * i], model.means[3 * i + 1], model.means[3 * i + 2]);
    // The cheap cull before any 2D covariance (forward_model.h, shared with the CUDA stage).
    if (fm::path_misses_image(
            mean, &model.log_scales[3 * i], q_max, static_cast<int>(path.size()),
            [&](int k) -> const fm::View& { return terms[static_cast<std::size_t>(k)].view; }, widening.slack,
            widening.margin_px, widening.motion_margin))
      return;
    const fm::Cov3 cov3 = fm::covariance_3d(
        {model.log_scales[3 * i], model.log_scales[3 * i + 1], model.log_scales[3 * i + 2]},
        {model.rotations[4 * i], model.rotations[4 * i + 1], model.rotations[4 * i + 2], model.rotations[4 * i + 3]});
    glm::vec2 means[kMaxPathCameras];
    glm::vec3 covs[kMaxPathCameras];
    int visible = 0;
    bool key_visible = false;
    for (std::size_t k = 0; k < path.size(); ++k) {
      const Camera& c = path[k];
      const glm::vec3 p = c.R * mean + c.t;
      if (!(p.z > c.near_plane) || p.z > c.far_plane) continue;
      const glm::vec3 cov2 = fm::covariance_2d(cov3, c.R, p, c.fx, c.fy, terms[k].view.tan_half_fov);
      if (cov2.x * cov2.z - cov2.y * cov2.y <= 0.0f) continue;
      means[visible] = {c.fx * p.x / p.z + c.cx - 0.5f, c.fy * p.y / p.z + c.cy - 0.5f};
      covs[visible] = cov2;
      if (k == 0) {
        key_visible = true;
        out.depth[i] = p.z;
      }
      ++visible;
    }
    // The key frame's depth orders the cached list, so a Gaussian behind the key camera is left
    // out even if a predicted pose would see it. A sub-frame that such a Gaussian (or one outside
    // every predicted frustum) would reach is turned into a key frame by unlisted_reach_image
    // (subframe_features.cpp), so it never shows as a hole.
    if (!key_visible) return;
    const fm::Trail trail =
        fm::build_trail(means, covs, visible, q_max, widening.slack, widening.margin_px, widening.motion_margin);
    glm::vec3 conic, trail_conic;
    if (!fm::conic_from_cov2d(covs[0], &conic) || !fm::conic_from_cov2d(trail.cov, &trail_conic)) return;
    const fm::TileRect rect =
        fm::trail_tile_rect(trail.mean0, trail.motion, trail.cov, trail.q_trail, key.width, key.height);
    const fm::TrailTileTest trail_test =
        fm::make_trail_tile_test(trail.mean0, trail.motion, trail_conic, trail.q_trail);
    uint32_t touched = 0;
    for (int ty = rect.y0; ty < rect.y1; ++ty)
      for (int tx = rect.x0; tx < rect.x1; ++tx)
        touched += fm::trail_touches_tile(trail_test, tx, ty, key.width, key.height) ? 1u : 0u;
    if (touched == 0) return;
    out.mean2d[i] = means[0];
    out.conic[i] = conic;
    // Drawn at the key view (fm::drawn_opacity); q_max stays the undrawn opacity's, which is no
    // smaller, so the trail's tiles still hold every pixel the sub-frames blend.
    out.opacity[i] = fm::drawn_opacity(opacity, covs[0], fm::lod_chunk_merged(lod_nodes, i / fm::kChunkSize));
    out.q_max[i] = q_max;
    out.color[i] =
        fm::sh_to_color_from(model.sh_degree, fm::HalfRoundedSh{&model.sh[static_cast<std::size_t>(K) * 3 * i]},
                             glm::normalize(mean - terms[0].position));
    out.tile_rect[i] = rect;
    out.tiles_touched[i] = touched;
    out.trail_mean0[i] = trail.mean0;
    out.trail_motion[i] = trail.motion;
    out.trail_cov[i] = trail.cov;
    out.trail_conic[i] = trail_conic;
    out.q_trail[i] = trail.q_trail;
  };
  // A chunk at a time, as the CUDA core takes a block per chunk; whole chunks that no path view
  // can show (fm::chunk_misses_path: the CUDA core's cull_path_chunks_kernel) are skipped, their
  // Gaussians left with tiles_touched = 0, and so are the chunks outside the key view's LOD cut.
  const fm::LodCut lod = fm::lod_cut(model.lod, terms[0].view, lod_error_px);
  const auto view_at = [&](int k) -> const fm::View& { return terms[static_cast<std::size_t>(k)].view; };
  parallel_for(chunks.size(), 16, [&](std::size_t c) {
    const std::size_t begin = c * fm::kChunkSize, end = std::min(n, begin + fm::kChunkSize);
    const bool culled =
        !lod.drawn(c) || fm::chunk_misses_path(chunks[c], static_cast<int>(path.size()), view_at, 1.0f + widening.slack,
                                               widening.margin_px, widening.motion_margin);
    for (std::size_t i = begin; i < end; ++i) {
      if (culled)
        out.tiles_touched[i] = 0;
      else
        gaussian(i);
    }
  });
}

}  // namespace catgs::cpu
