// .splat reader (layout, axes and losses in splat_file.h).
#include "scene/splat_file.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <vector>

namespace catgs {

namespace {

constexpr std::size_t kRecordBytes = 32;
constexpr float kShC0 = 0.28209479177387814f;

[[noreturn]] void fail(const std::string& path, const std::string& problem) { throw SceneFileError(path, problem); }

float f32_at(const uint8_t* at) {
  float v;
  std::memcpy(&v, at, 4);
  return v;
}

float opacity_logit_of_byte(uint8_t a) {
  if (a == 0) return -kOpacityLogitLimit;
  if (a == 255) return kOpacityLogitLimit;
  const float t = static_cast<float>(a) / 255.0f;
  return std::log(t / (1.0f - t));
}

// One record into row i of m.
void decode_record(const uint8_t* r, std::size_t i, GaussianModel& m, const std::string& path) {
  static const char* kAxis[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    const float p = f32_at(r + 4 * a), s = f32_at(r + 12 + 4 * a);
    if (!std::isfinite(p))
      fail(path, "non-finite position " + std::string(kAxis[a]) + " in record " + std::to_string(i));
    if (!(s > 0.0f) || !std::isfinite(s))
      fail(path, "scale " + std::string(kAxis[a]) + " of record " + std::to_string(i) + " is not a positive number");
    m.means[3 * i + a] = p;
    m.log_scales[3 * i + a] = std::log(s);
    m.sh[3 * i + a] = (static_cast<float>(r[24 + a]) / 255.0f - 0.5f) / kShC0;
  }
  m.opacity_logits[i] = opacity_logit_of_byte(r[27]);
  float q[4], len2 = 0;
  for (int k = 0; k < 4; ++k) {
    q[k] = static_cast<float>(r[28 + k]) / 127.5f - 1.0f;
    len2 += q[k] * q[k];
  }
  const float len = std::sqrt(len2);
  for (int k = 0; k < 4; ++k) m.rotations[4 * i + k] = len > 0 ? q[k] / len : (k == 0 ? 1.0f : 0.0f);
}

}  // namespace

bool looks_like_splat(const std::vector<uint8_t>& head, std::uint64_t file_size) {
  if (file_size == 0 || file_size % kRecordBytes != 0 || head.size() < kRecordBytes) return false;
  const std::size_t records = std::min<std::size_t>(head.size() / kRecordBytes, 128);
  for (std::size_t i = 0; i < records; ++i) {
    const uint8_t* r = &head[i * kRecordBytes];
    for (int a = 0; a < 3; ++a) {
      const float p = f32_at(r + 4 * a), s = f32_at(r + 12 + 4 * a);
      if (!(std::fabs(p) < 1e7f) || !(s > 0.0f && s < 1e7f)) return false;
    }
    float len2 = 0;
    for (int k = 0; k < 4; ++k) {
      const float q = static_cast<float>(r[28 + k]) / 127.5f - 1.0f;
      len2 += q * q;
    }
    if (!(len2 >= 0.8f && len2 <= 1.2f)) return false;
  }
  return true;
}

GaussianModel read_splat(const std::string& path, const LoadProgress& progress) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open file");
  const std::vector<uint8_t> bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  if (bytes.empty()) fail(path, "empty .splat file");
  if (bytes.size() % kRecordBytes != 0)
    fail(path, ".splat size " + std::to_string(bytes.size()) + " is not a multiple of 32-byte records");
  GaussianModel m;
  m.sh_degree = 0;
  m.resize(bytes.size() / kRecordBytes);
  const ProgressSteps steps(progress, m.size());
  for (std::size_t i = 0; i < m.size(); ++i) {
    steps.at(i);
    decode_record(&bytes[i * kRecordBytes], i, m, path);
  }
  steps.done();
  return m;
}

}  // namespace catgs
