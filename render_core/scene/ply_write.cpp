// Scene writers: INRIA 3DGS PLY and SuperSplat compressed PLY.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "scene/ply_io.h"
#include "scene/quantize.h"

namespace catgs {

namespace {

constexpr float kShC0 = 0.28209479177387814f;

std::ofstream open_out(const std::string& path) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw SceneFileError(path, "cannot open for writing");
  return out;
}

template <typename T>
void put(std::string& buf, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  buf.append(b, sizeof(T));
}

float sh_rest(const GaussianModel& m, std::size_t i, int rest_index) {
  const int K = m.sh_coeffs();
  const int c = rest_index / (K - 1), k = 1 + rest_index % (K - 1);
  return m.sh[(i * static_cast<std::size_t>(K) + static_cast<std::size_t>(k)) * 3 + static_cast<std::size_t>(c)];
}

using quant::normalized;
uint32_t quantize(float t, int bits) { return quant::unorm_bits(t, bits); }

void finish(std::ofstream& out, const std::string& header, const std::string& body, const std::string& path) {
  out.write(header.data(), static_cast<std::streamsize>(header.size()));
  out.write(body.data(), static_cast<std::streamsize>(body.size()));
  if (!out) throw SceneFileError(path, "write failed");
}

}  // namespace

void write_inria_ply(const GaussianModel& m, const std::string& path) {
  auto out = open_out(path);
  const int rest = 3 * (m.sh_coeffs() - 1);
  std::ostringstream h;
  h << "ply\nformat binary_little_endian 1.0\nelement vertex " << m.size() << "\n";
  for (const char* p : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"})
    h << "property float " << p << "\n";
  for (int j = 0; j < rest; ++j) h << "property float f_rest_" << j << "\n";
  for (const char* p : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
    h << "property float " << p << "\n";
  h << "end_header\n";
  std::string body;
  body.reserve(m.size() * static_cast<std::size_t>(17 + rest) * 4);
  const std::size_t K = static_cast<std::size_t>(m.sh_coeffs());
  for (std::size_t i = 0; i < m.size(); ++i) {
    for (int a = 0; a < 3; ++a) put(body, m.means[3 * i + a]);
    for (int a = 0; a < 3; ++a) put(body, 0.0f);
    for (int a = 0; a < 3; ++a) put(body, m.sh[i * K * 3 + a]);
    for (int j = 0; j < rest; ++j) put(body, sh_rest(m, i, j));
    put(body, m.opacity_logits[i]);
    for (int a = 0; a < 3; ++a) put(body, m.log_scales[3 * i + a]);
    for (int a = 0; a < 4; ++a) put(body, m.rotations[4 * i + a]);
  }
  finish(out, h.str(), body, path);
}

void write_compressed_ply(const GaussianModel& m, const std::string& path) {
  auto out = open_out(path);
  const std::size_t n = m.size(), chunks = (n + 255) / 256;
  const int rest = 3 * (m.sh_coeffs() - 1);
  const std::size_t K = static_cast<std::size_t>(m.sh_coeffs());
  std::ostringstream h;
  h << "ply\nformat binary_little_endian 1.0\ncomment written by catgs (SuperSplat compressed PLY, rotations in "
       "packRot order)\n"
    << "element chunk " << chunks << "\n";
  for (const char* p :
       {"min_x", "min_y", "min_z", "max_x", "max_y", "max_z", "min_scale_x", "min_scale_y", "min_scale_z",
        "max_scale_x", "max_scale_y", "max_scale_z", "min_r", "min_g", "min_b", "max_r", "max_g", "max_b"})
    h << "property float " << p << "\n";
  h << "element vertex " << n << "\n";
  for (const char* p : {"packed_position", "packed_rotation", "packed_scale", "packed_color"})
    h << "property uint " << p << "\n";
  if (rest > 0) {
    h << "element sh " << n << "\n";
    for (int j = 0; j < rest; ++j) h << "property uchar f_rest_" << j << "\n";
  }
  h << "end_header\n";

  auto colour = [&](std::size_t i, int a) { return m.sh[i * K * 3 + a] * kShC0 + 0.5f; };
  std::string chunk_body, vertex_body, sh_body;
  for (std::size_t c = 0; c < chunks; ++c) {
    const std::size_t begin = c * 256, end = std::min(n, begin + 256);
    float lo[9], hi[9];  // position, log-scale, colour
    std::fill(lo, lo + 9, INFINITY);
    std::fill(hi, hi + 9, -INFINITY);
    for (std::size_t i = begin; i < end; ++i)
      for (int a = 0; a < 3; ++a) {
        const float v[3] = {m.means[3 * i + a], std::clamp(m.log_scales[3 * i + a], -20.0f, 20.0f), colour(i, a)};
        for (int g = 0; g < 3; ++g) {
          lo[3 * g + a] = std::min(lo[3 * g + a], v[g]);
          hi[3 * g + a] = std::max(hi[3 * g + a], v[g]);
        }
      }
    for (int g = 0; g < 3; ++g) {
      for (int a = 0; a < 3; ++a) put(chunk_body, lo[3 * g + a]);
      for (int a = 0; a < 3; ++a) put(chunk_body, hi[3 * g + a]);
    }
    for (std::size_t i = begin; i < end; ++i) {
      uint32_t bits[3][3];  // position, scale, colour quantized
      for (int a = 0; a < 3; ++a) {
        bits[0][a] = quantize(normalized(m.means[3 * i + a], lo[a], hi[a]), a == 1 ? 10 : 11);
        bits[1][a] = quantize(normalized(std::clamp(m.log_scales[3 * i + a], -20.0f, 20.0f), lo[3 + a], hi[3 + a]),
                              a == 1 ? 10 : 11);
        bits[2][a] = quantize(normalized(colour(i, a), lo[6 + a], hi[6 + a]), 8);
      }
      put(vertex_body, (bits[0][0] << 21) | (bits[0][1] << 11) | bits[0][2]);
      // Rotation: smallest-three over (rot_0..rot_3) = INRIA (w, x, y, z), SuperSplat's packRot
      // order (quantize.h).
      put(vertex_body, quant::pack_rotation(&m.rotations[4 * i]));
      put(vertex_body, (bits[1][0] << 21) | (bits[1][1] << 11) | bits[1][2]);
      const float alpha = 1.0f / (1.0f + std::exp(-m.opacity_logits[i]));
      put(vertex_body, (bits[2][0] << 24) | (bits[2][1] << 16) | (bits[2][2] << 8) | quantize(alpha, 8));
      for (int j = 0; j < rest; ++j) {
        const float t = (sh_rest(m, i, j) + 4.0f) / 8.0f * 256.0f;
        put(sh_body, static_cast<uint8_t>(std::clamp(std::floor(t), 0.0f, 255.0f)));
      }
    }
  }
  finish(out, h.str(), chunk_body + vertex_body + sh_body, path);
}

}  // namespace catgs
