#include "brute_force_renderer.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace catgs::test {
namespace {

using dvec3 = glm::dvec3;
using dmat3 = glm::dmat3;

struct Splat {
  double mx, my, depth, opacity;
  double ca, cb, cc;  // conic
  dvec3 color;
  int x0, x1, y0, y1;  // pixels it may reach (inclusive)
};

}  // namespace

// Real SH basis (the sign convention of the reference 3DGS), degree <= 3, at unit direction d.
void sh_basis(dvec3 d, double* y) {
  const double x = d.x, yy = d.y, z = d.z;
  y[0] = 0.28209479177387814;
  y[1] = -0.4886025119029199 * yy;
  y[2] = 0.4886025119029199 * z;
  y[3] = -0.4886025119029199 * x;
  y[4] = 1.0925484305920792 * x * yy;
  y[5] = -1.0925484305920792 * yy * z;
  y[6] = 0.31539156525252005 * (2 * z * z - x * x - yy * yy);
  y[7] = -1.0925484305920792 * x * z;
  y[8] = 0.5462742152960396 * (x * x - yy * yy);
  y[9] = -0.5900435899266435 * yy * (3 * x * x - yy * yy);
  y[10] = 2.890611442640554 * x * yy * z;
  y[11] = -0.4570457994644658 * yy * (4 * z * z - x * x - yy * yy);
  y[12] = 0.3731763325901154 * z * (2 * z * z - 3 * x * x - 3 * yy * yy);
  y[13] = -0.4570457994644658 * x * (4 * z * z - x * x - yy * yy);
  y[14] = 1.445305721320277 * z * (x * x - yy * yy);
  y[15] = -0.5900435899266435 * x * (x * x - 3 * yy * yy);
}

Image brute_force_render(const GaussianModel& m, const Camera& cam, bool vanilla, glm::vec3 background) {
  const int W = cam.width, H = cam.height;
  const dmat3 Rw(cam.R);
  const dvec3 tw(cam.t);
  const dvec3 eye = -(glm::transpose(Rw) * tw);
  const int K = m.sh_coeffs();
  std::vector<Splat> splats;
  std::vector<std::size_t> index;
  for (std::size_t i = 0; i < m.size(); ++i) {
    const dvec3 mean(m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]);
    const dvec3 p = Rw * mean + tw;
    if (!(p.z > cam.near_plane) || p.z > cam.far_plane) continue;
    // Sigma = R S S R^T with R from the normalised quaternion (w, x, y, z).
    glm::dvec4 q(m.rotations[4 * i], m.rotations[4 * i + 1], m.rotations[4 * i + 2], m.rotations[4 * i + 3]);
    q /= glm::length(q);
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    const double rot[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                              {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                              {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
    double sigma[3][3] = {};
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        for (int k = 0; k < 3; ++k) sigma[r][c] += rot[r][k] * rot[c][k] * std::exp(2.0 * m.log_scales[3 * i + k]);
    // Jacobian at the mean clamped to 1.3x the half field of view.
    const double limx = 1.3 * W / (2.0 * cam.fx), limy = 1.3 * H / (2.0 * cam.fy);
    const double jx = std::clamp(p.x / p.z, -limx, limx) * p.z, jy = std::clamp(p.y / p.z, -limy, limy) * p.z;
    const double J[2][3] = {{cam.fx / p.z, 0, -cam.fx * jx / (p.z * p.z)},
                            {0, cam.fy / p.z, -cam.fy * jy / (p.z * p.z)}};
    double T[2][3] = {};  // J * W (W = world-to-camera rotation, row r col c = Rw[c][r])
    for (int r = 0; r < 2; ++r)
      for (int c = 0; c < 3; ++c)
        for (int k = 0; k < 3; ++k) T[r][c] += J[r][k] * Rw[c][k];
    double cov[2][2] = {};
    for (int r = 0; r < 2; ++r)
      for (int c = 0; c < 2; ++c)
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b) cov[r][c] += T[r][a] * sigma[a][b] * T[c][b];
    cov[0][0] += 0.3;
    cov[1][1] += 0.3;
    const double det = cov[0][0] * cov[1][1] - cov[0][1] * cov[0][1];
    if (det <= 0) continue;
    Splat s;
    s.mx = cam.fx * p.x / p.z + cam.cx - 0.5;
    s.my = cam.fy * p.y / p.z + cam.cy - 0.5;
    s.depth = p.z;
    s.opacity = 1.0 / (1.0 + std::exp(-static_cast<double>(m.opacity_logits[i])));
    s.ca = cov[1][1] / det;
    s.cb = -cov[0][1] / det;
    s.cc = cov[0][0] / det;
    if (vanilla) {
      const double mid = 0.5 * (cov[0][0] + cov[1][1]);
      const double radius = std::ceil(3.0 * std::sqrt(mid + std::sqrt(std::max(0.1, mid * mid - det))));
      const int tw_ = (W + 15) / 16, th_ = (H + 15) / 16;
      auto tile = [](double v, int hi) { return std::clamp(static_cast<int>(v / 16.0), 0, hi); };
      const int tx0 = tile(s.mx - radius, tw_), tx1 = tile(s.mx + radius + 15, tw_);
      const int ty0 = tile(s.my - radius, th_), ty1 = tile(s.my + radius + 15, th_);
      if (tx1 <= tx0 || ty1 <= ty0) continue;
      s.x0 = tx0 * 16, s.x1 = std::min(W, tx1 * 16) - 1, s.y0 = ty0 * 16, s.y1 = std::min(H, ty1 * 16) - 1;
    } else {
      if (s.opacity < 1.0 / 255.0) continue;
      const double qmax = 2.0 * std::log(255.0 * s.opacity) + 0.01;
      const double hx = std::sqrt(qmax * cov[0][0]), hy = std::sqrt(qmax * cov[1][1]);
      s.x0 = std::max(0, static_cast<int>(std::floor(s.mx - hx)));
      s.x1 = std::min(W - 1, static_cast<int>(std::ceil(s.mx + hx)));
      s.y0 = std::max(0, static_cast<int>(std::floor(s.my - hy)));
      s.y1 = std::min(H - 1, static_cast<int>(std::ceil(s.my + hy)));
      if (s.x1 < s.x0 || s.y1 < s.y0) continue;
    }
    double basis[16];
    sh_basis(glm::normalize(mean - eye), basis);
    dvec3 c(0.0);
    for (int k = 0; k < K; ++k)
      for (int ch = 0; ch < 3; ++ch)
        c[ch] +=
            basis[k] *
            m.sh[(i * static_cast<std::size_t>(K) + static_cast<std::size_t>(k)) * 3 + static_cast<std::size_t>(ch)];
    s.color = glm::max(c + 0.5, dvec3(0.0));
    splats.push_back(s);
    index.push_back(i);
  }
  // Front to back: by depth, ties by Gaussian index.
  std::vector<std::size_t> order(splats.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    const float da = static_cast<float>(splats[a].depth), db = static_cast<float>(splats[b].depth);
    return da != db ? da < db : index[a] < index[b];
  });
  // Per pixel candidate lists, filled in depth order.
  std::vector<std::vector<uint32_t>> lists(static_cast<std::size_t>(W) * H);
  for (std::size_t k : order) {
    const Splat& s = splats[k];
    for (int py = s.y0; py <= s.y1; ++py)
      for (int px = s.x0; px <= s.x1; ++px)
        lists[static_cast<std::size_t>(py) * W + px].push_back(static_cast<uint32_t>(k));
  }
  Image img;
  img.width = W;
  img.height = H;
  img.rgb.resize(static_cast<std::size_t>(W) * H * 3);
  img.rgba8.resize(static_cast<std::size_t>(W) * H * 4);
  for (int py = 0; py < H; ++py) {
    for (int px = 0; px < W; ++px) {
      double T = 1.0;
      dvec3 C(0.0);
      for (uint32_t k : lists[static_cast<std::size_t>(py) * W + px]) {
        const Splat& s = splats[k];
        const double dx = s.mx - px, dy = s.my - py;
        const double q = s.ca * dx * dx + 2 * s.cb * dx * dy + s.cc * dy * dy;
        const double alpha = std::min(0.99, s.opacity * std::exp(-0.5 * q));
        if (alpha < 1.0 / 255.0) continue;
        if (T * (1.0 - alpha) < 1e-4) break;  // stops before the Gaussian that would take T below 1e-4
        C += s.color * (alpha * T);
        T *= 1.0 - alpha;
      }
      C += T * dvec3(background);
      const std::size_t p = static_cast<std::size_t>(py) * W + px;
      for (int ch = 0; ch < 3; ++ch) {
        img.rgb[3 * p + ch] = static_cast<float>(C[ch]);
        img.rgba8[4 * p + ch] = static_cast<uint8_t>(std::lround(std::clamp(C[ch], 0.0, 1.0) * 255.0));
      }
      img.rgba8[4 * p + 3] = 255;
    }
  }
  return img;
}

}  // namespace catgs::test
