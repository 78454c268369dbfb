// Depth probe (pixel_depth.h): one ray through the forward model, composited front to back.
#include "cpu/pixel_depth.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "forward_model/forward_model.h"

namespace catgs::cpu {

namespace {

// (depth, alpha) of each Gaussian that reaches the sample point `s` (pixel units), unsorted.
std::vector<std::pair<float, float>> ray_hits(const GaussianModel& model, const Camera& camera, glm::vec2 s,
                                              const std::vector<fm::ChunkBounds>* chunks) {
  // A 1 x 1 view whose only pixel is `s`: edges_beyond() then rejects every Gaussian whose
  // conservative screen radius does not reach s, before its covariance is computed. The field of
  // view (the Jacobian's clamp) stays the real camera's.
  fm::View one = fm::view_of(camera);
  one.cx -= s.x;
  one.cy -= s.y;
  one.width = one.height = 1;
  const glm::vec2 tan_half_fov = fm::view_of(camera).tan_half_fov;

  std::vector<std::pair<float, float>> hits;
  if (chunks && chunks->size() != fm::chunk_count(model.size()))
    throw std::invalid_argument("depth probe: chunk bounds of another scene");
  for (std::size_t i = 0; i < model.size(); ++i) {
    // A chunk that cannot reach the one pixel: on to the next chunk.
    // With LOD, the leaves only (full detail: the depth of what the scene really holds).
    if (i % fm::kChunkSize == 0 &&
        ((!model.lod.empty() && !fm::lod_chunk_drawn(model.lod.data(), i / fm::kChunkSize, one, 0.0f)) ||
         (chunks && fm::chunk_outside_view((*chunks)[i / fm::kChunkSize], one)))) {
      i += fm::kChunkSize - 1;
      continue;
    }
    const glm::vec3 mean(model.means[3 * i], model.means[3 * i + 1], model.means[3 * i + 2]);
    const glm::vec3 p = camera.R * mean + camera.t;
    if (!(p.z > camera.near_plane) || p.z > camera.far_plane) continue;
    const float opacity = fm::sigmoid(model.opacity_logits[i]);
    const float q_max = fm::opacity_aware_qmax(opacity);
    if (!(q_max > 0.0f)) continue;  // never reaches alpha 1/255
    const float* log_scale = &model.log_scales[3 * i];
    if (fm::edges_beyond(p, fm::max_scale_of(log_scale), q_max, one) != 0u) continue;
    const float* q = &model.rotations[4 * i];
    const fm::Cov3 cov3 = fm::covariance_3d({log_scale[0], log_scale[1], log_scale[2]}, {q[0], q[1], q[2], q[3]});
    const glm::vec3 cov2 = fm::covariance_2d(cov3, camera.R, p, camera.fx, camera.fy, tan_half_fov);
    glm::vec3 conic;
    if (!fm::conic_from_cov2d(cov2, &conic)) continue;
    const glm::vec2 mean2d(camera.fx * p.x / p.z + camera.cx - 0.5f, camera.fy * p.y / p.z + camera.cy - 0.5f);
    // As blend_tile.cpp: d = pixel - mean, alpha = min(0.99, opacity exp(power)), skipped < 1/255.
    const float power = fm::gaussian_power(conic, s.x - mean2d.x, s.y - mean2d.y);
    if (power > 0.0f) continue;
    const float alpha = std::min(fm::kMaxAlpha, opacity * std::exp(power));
    if (alpha < fm::kMinAlpha) continue;
    hits.emplace_back(p.z, alpha);
  }
  return hits;
}

}  // namespace

PixelDepth probe_pixel_depth(const GaussianModel& model, const Camera& camera, double x, double y,
                             const std::vector<fm::ChunkBounds>* chunks) {
  validate_camera(camera);
  if (!std::isfinite(x) || !std::isfinite(y)) throw std::invalid_argument("pixel coordinates are NaN or Inf");
  if (x < 0.0 || y < 0.0 || x >= camera.width || y >= camera.height)
    throw std::invalid_argument("pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") is outside the " +
                                std::to_string(camera.width) + "x" + std::to_string(camera.height) + " view");
  const glm::vec2 s(static_cast<float>(x) - 0.5f, static_cast<float>(y) - 0.5f);
  std::vector<std::pair<float, float>> hits = ray_hits(model, camera, s, chunks);
  // Front to back; equal depths keep a fixed order so the answer is deterministic.
  std::sort(hits.begin(), hits.end());

  PixelDepth out;
  out.contributors = hits.size();
  float T = 1.0f;
  for (const auto& [depth, alpha] : hits) {
    const float next = T * (1.0f - alpha);
    if (next < fm::kMinTransmittance) break;  // the renderer stops here without blending it
    T = next;
    if (!out.hit && T <= kSurfaceTransmittance) {
      out.hit = true;
      out.depth = depth;
    }
  }
  out.opacity = 1.0f - T;
  if (out.hit) {
    const glm::vec3 ray_cam((static_cast<float>(x) - camera.cx) / camera.fx,
                            (static_cast<float>(y) - camera.cy) / camera.fy, 1.0f);
    out.point = camera.position() + glm::transpose(camera.R) * (out.depth * ray_cam);
  }
  return out;
}

}  // namespace catgs::cpu
