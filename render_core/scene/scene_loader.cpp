// Scene loading: every format by content (format_detect.h); INRIA 3DGS PLY and SuperSplat
// compressed PLY here, the others in their own files.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <filesystem>
#include <limits>
#include <string>

#include "scene/ply_io.h"
#include "scene/quantize.h"
#include "ply_format.h"
#include "scene/load_blocks.h"
#include "scene/format_detect.h"
#include "scene/compact_file.h"
#include "scene/splat_file.h"
#include "scene/gltf_file.h"
#include "scene/scene_peek.h"
#include "scene/sog_file.h"
#include "scene/spz_file.h"

namespace catgs {

namespace {

constexpr float kShC0 = 0.28209479177387814f;

// A parallel walk over a PLY's rows in blocks of kRowsPerBlock (load_blocks.h): each block hands
// its rows' file pages back when done (ply::File::release_rows: they leave this process's memory,
// so the load peaks near the model's size rather than the model's plus the file's), and the
// loading thread reports progress between its blocks.
constexpr uint64_t kRowsPerBlock = 8192;
static_assert(kRowsPerBlock % 256 == 0, "blocks start at a compressed PLY chunk");

// rows(begin, end) reads rows [begin, end) in order, throwing at the first bad one.
void walk_rows(const ply::File& f, std::initializer_list<const ply::Element*> per_row, const ply::Element* per_chunk,
               uint64_t count, const LoadOptions& options, const LoadProgress& progress,
               const std::function<void(uint64_t, uint64_t)>& rows) {
  const uint64_t blocks = (count + kRowsPerBlock - 1) / kRowsPerBlock;
  const std::vector<const ply::Element*> elements(per_row);
  run_blocks(
      blocks, options.reference ? 1 : options.threads,
      [&](uint64_t b) {
        const uint64_t begin = b * kRowsPerBlock, end = std::min(count, begin + kRowsPerBlock);
        rows(begin, end);
        for (const ply::Element* e : elements)
          if (e) f.release_rows(*e, begin, end);
        if (per_chunk) f.release_rows(*per_chunk, begin / 256, (end + 255) / 256);
      },
      [&](uint64_t done) {
        if (progress && done < blocks) progress(done * kRowsPerBlock, count);
      });
  if (progress) progress(count, count);
}

// f_rest count -> SH degree, or -1.
int degree_of_rest_count(int rest) {
  for (int d = 0; d <= kMaxShDegree; ++d)
    if (3 * (sh_coeff_count(d) - 1) == rest) return d;
  return -1;
}

// Number of f_rest_* properties, requiring them to be f_rest_0 .. f_rest_{M-1}.
int count_rest(const ply::Element& e, const std::string& path) {
  int m = 0;
  for (const auto& p : e.properties)
    if (p.name.rfind("f_rest_", 0) == 0) ++m;
  for (int j = 0; j < m; ++j)
    if (e.find("f_rest_" + std::to_string(j)) < 0)
      throw SceneFileError(path, "f_rest properties are not numbered 0.." + std::to_string(m - 1));
  const int degree = degree_of_rest_count(m);
  if (degree < 0)
    throw SceneFileError(path, std::to_string(m) + " f_rest properties match no SH degree (0, 9, 24 or 45)");
  return m;
}

int require(const ply::Element& e, const std::string& name, const std::string& path) {
  const int i = e.find(name);
  if (i < 0) throw SceneFileError(path, "element '" + e.name + "' lacks property '" + name + "'");
  return i;
}

// Stores v after checking it is finite and within float range (a double past it would make the
// conversion undefined).
// (The message is built only on failure: this runs for every value of a file.)
float finite(double v, const ply::Element& e, uint64_t row, int prop, const std::string& path) {
  const bool bad_value = !std::isfinite(v);
  if (bad_value || std::fabs(v) > std::numeric_limits<float>::max())
    throw SceneFileError(path, std::string(bad_value ? "non-finite value" : "value outside float range") +
                                   " in element '" + e.name + "' row " + std::to_string(row) + " property '" +
                                   e.properties[static_cast<std::size_t>(prop)].name + "'");
  return static_cast<float>(v);
}

// An opacity logit: +-inf (alpha 1 or 0) clamps to +-kOpacityLogitLimit; NaN fails as finite() does.
float opacity_logit(double v, const ply::Element& e, uint64_t row, int prop, const std::string& path) {
  if (std::isinf(v)) return v > 0 ? kOpacityLogitLimit : -kOpacityLogitLimit;
  return finite(v, e, row, prop, path);
}

// Requires property `index` of `e` to have type `type`: the compressed format's packed fields
// are bit fields, and reading another type as them would convert out-of-range values.
void require_type(const ply::Element& e, int index, ply::Type type, const char* type_name, const std::string& path) {
  const ply::Property& p = e.properties[static_cast<std::size_t>(index)];
  if (p.type != type)
    throw SceneFileError(path, "property '" + p.name + "' of element '" + e.name + "' must be " + type_name);
}

// Where f_rest_j goes among a Gaussian's K x 3 SH floats: the INRIA layout is channel-major,
// f_rest[c * (K - 1) + (k - 1)], ours coefficient-major, sh[k * 3 + c].
std::size_t rest_slot(int K, int rest_index) {
  const int c = rest_index / (K - 1), k = 1 + rest_index % (K - 1);
  return static_cast<std::size_t>(k) * 3 + static_cast<std::size_t>(c);
}

// The INRIA properties a Gaussian is read from: property indices, and where each goes.
struct InriaColumns {
  int idx[14];                // x y z, f_dc_0..2, opacity, scale_0..2, rot_0..3
  std::vector<int> rest_idx;  // f_rest_j
  std::vector<std::size_t> rest_slot;
  bool f32 = false;  // a binary file whose every property read is float32
};

// One row through ply::File::value (any type, ascii or binary), each value checked: the serial
// reference, the reader of files that are not all float32, and the one that names a bad value.
void read_inria_row(const ply::File& f, const ply::Element& v, const InriaColumns& c, uint64_t i, GaussianModel& m) {
  auto get = [&](int prop) { return finite(f.value(v, i, prop), v, i, prop, f.path); };
  const std::size_t K3 = static_cast<std::size_t>(m.sh_coeffs()) * 3;
  for (int a = 0; a < 3; ++a) {
    m.means[3 * i + a] = get(c.idx[a]);
    m.sh[i * K3 + a] = get(c.idx[3 + a]);
    m.log_scales[3 * i + a] = get(c.idx[7 + a]);
  }
  m.opacity_logits[i] = opacity_logit(f.value(v, i, c.idx[6]), v, i, c.idx[6], f.path);
  for (int a = 0; a < 4; ++a) m.rotations[4 * i + a] = get(c.idx[10 + a]);
  for (std::size_t j = 0; j < c.rest_idx.size(); ++j) m.sh[i * K3 + c.rest_slot[j]] = get(c.rest_idx[j]);
}

// The same row of an all-float32 binary file, read straight from its bytes (the common case:
// every trained scene). Returns false, leaving the row to read_inria_row's message, when a value
// is NaN or infinite (an opacity may be infinite: clamped as opacity_logit clamps it).
bool read_inria_row_f32(const uint8_t* row, const ply::Element& v, const InriaColumns& c, uint64_t i,
                        GaussianModel& m) {
  auto at = [&](int prop) {
    float x;
    std::memcpy(&x, row + v.properties[static_cast<std::size_t>(prop)].offset, sizeof x);
    return x;
  };
  bool ok = true;
  auto get = [&](int prop) {
    const float x = at(prop);
    ok &= std::isfinite(x);
    return x;
  };
  const std::size_t K3 = static_cast<std::size_t>(m.sh_coeffs()) * 3;
  for (int a = 0; a < 3; ++a) {
    m.means[3 * i + a] = get(c.idx[a]);
    m.sh[i * K3 + a] = get(c.idx[3 + a]);
    m.log_scales[3 * i + a] = get(c.idx[7 + a]);
  }
  const float o = at(c.idx[6]);
  ok &= !std::isnan(o);
  m.opacity_logits[i] = std::isinf(o) ? (o > 0 ? kOpacityLogitLimit : -kOpacityLogitLimit) : o;
  for (int a = 0; a < 4; ++a) m.rotations[4 * i + a] = get(c.idx[10 + a]);
  for (std::size_t j = 0; j < c.rest_idx.size(); ++j) m.sh[i * K3 + c.rest_slot[j]] = get(c.rest_idx[j]);
  return ok;
}

GaussianModel load_inria(const ply::File& f, const ply::Element& v, const LoadOptions& options,
                         const LoadProgress& progress) {
  const std::string& path = f.path;
  GaussianModel m;
  const int rest = count_rest(v, path);
  m.sh_degree = degree_of_rest_count(rest);
  m.resize(v.count);
  const char* names[] = {"x",       "y",       "z",       "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                         "scale_0", "scale_1", "scale_2", "rot_0",  "rot_1",  "rot_2",  "rot_3"};
  InriaColumns c;
  for (int k = 0; k < 14; ++k) c.idx[k] = require(v, names[k], path);
  for (int j = 0; j < rest; ++j) {
    c.rest_idx.push_back(v.find("f_rest_" + std::to_string(j)));
    c.rest_slot.push_back(rest_slot(m.sh_coeffs(), j));
  }
  c.f32 = !f.ascii && !options.reference;
  for (int k = 0; k < 14; ++k) c.f32 &= v.properties[static_cast<std::size_t>(c.idx[k])].type == ply::Type::f32;
  for (const int k : c.rest_idx) c.f32 &= v.properties[static_cast<std::size_t>(k)].type == ply::Type::f32;

  walk_rows(f, {&v}, nullptr, v.count, options, progress, [&](uint64_t begin, uint64_t end) {
    const uint8_t* base = c.f32 ? f.bytes.data() + v.data_offset : nullptr;
    for (uint64_t i = begin; i < end; ++i)
      if (!c.f32 || !read_inria_row_f32(base + i * v.row_size, v, c, i, m)) read_inria_row(f, v, c, i, m);
  });
  return m;
}

using quant::unorm;

// The property indices of a compressed PLY (chunk ranges, packed fields, SH codes).
struct CompressedColumns {
  int range_idx[12];
  int color_idx[6];
  bool color_ranges = true;
  int pp, pr, ps, pc;
  std::vector<int> rest_idx;
  std::vector<std::size_t> rest_slot;
};

// Longer than the rest on purpose: it decodes every packed property of Gaussian i next to the
// chunk ranges it is dequantised with, in the order SuperSplat's writer packs them, so the format
// can be read against its source line by line. `r` and `cr` hold the ranges of i's chunk.
void decode_compressed_row(const ply::File& f, const ply::Element& v, const ply::Element* sh,
                           const CompressedColumns& c, const float r[12], const float cr[6], uint64_t i,
                           GaussianModel& m) {
  const std::size_t K3 = static_cast<std::size_t>(m.sh_coeffs()) * 3;
  const auto pos = static_cast<uint32_t>(f.value(v, i, c.pp));
  const auto rot = static_cast<uint32_t>(f.value(v, i, c.pr));
  const auto scl = static_cast<uint32_t>(f.value(v, i, c.ps));
  const auto col = static_cast<uint32_t>(f.value(v, i, c.pc));
  const float t_pos[3] = {unorm(pos >> 21, 11), unorm(pos >> 11, 10), unorm(pos, 11)};
  const float t_scl[3] = {unorm(scl >> 21, 11), unorm(scl >> 11, 10), unorm(scl, 11)};
  for (int a = 0; a < 3; ++a) {
    m.means[3 * i + a] = r[a] + (r[3 + a] - r[a]) * t_pos[a];
    m.log_scales[3 * i + a] = r[6 + a] + (r[9 + a] - r[6 + a]) * t_scl[a];
    const float c01 = unorm(col >> (24 - 8 * a), 8);
    const float colour = cr[a] + (cr[3 + a] - cr[a]) * c01;
    m.sh[i * K3 + a] = (colour - 0.5f) / kShC0;
  }
  // Opacity 0 or 1 has an infinite logit: clamped as the INRIA reader clamps one.
  const float alpha = unorm(col, 8);
  m.opacity_logits[i] = alpha <= 0.0f ? -kOpacityLogitLimit
                        : alpha >= 1.0f
                            ? kOpacityLogitLimit
                            : std::clamp(-std::log(1.0f / alpha - 1.0f), -kOpacityLogitLimit, kOpacityLogitLimit);
  // Smallest-three quaternion over (rot_0..rot_3) = INRIA (w, x, y, z), as SuperSplat's
  // packRot(rot_0, rot_1, rot_2, rot_3) writes it and PlayCanvas's engine reads it (quantize.h).
  quant::unpack_rotation(rot, &m.rotations[4 * i]);
  for (std::size_t j = 0; j < c.rest_idx.size(); ++j) {
    const auto q = static_cast<uint32_t>(f.value(*sh, i, c.rest_idx[j]));
    // Bucket centres, except that 0 and 255 decode to the range ends -4 and 4 (as splat-transform
    // and PlayCanvas's engine read them).
    const float t = q == 0 ? 0.0f : q == 255 ? 1.0f : (static_cast<float>(q) + 0.5f) / 256.0f;
    m.sh[i * K3 + c.rest_slot[j]] = t * 8.0f - 4.0f;
  }
}

GaussianModel load_compressed(const ply::File& f, const ply::Element& chunk, const ply::Element& v,
                              const LoadOptions& options, const LoadProgress& progress) {
  const std::string& path = f.path;
  if (chunk.count != (v.count + 255) / 256)
    throw SceneFileError(path, std::to_string(chunk.count) + " chunks cannot hold " + std::to_string(v.count) +
                                   " Gaussians (256 per chunk)");
  CompressedColumns c;
  const char* range_names[] = {"min_x",       "min_y",       "min_z",       "max_x",
                               "max_y",       "max_z",       "min_scale_x", "min_scale_y",
                               "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z"};
  for (int k = 0; k < 12; ++k) c.range_idx[k] = require(chunk, range_names[k], path);
  const char* color_names[] = {"min_r", "min_g", "min_b", "max_r", "max_g", "max_b"};
  for (int k = 0; k < 6; ++k) c.color_ranges &= (c.color_idx[k] = chunk.find(color_names[k])) >= 0;
  c.pp = require(v, "packed_position", path);
  c.pr = require(v, "packed_rotation", path);
  c.ps = require(v, "packed_scale", path);
  c.pc = require(v, "packed_color", path);
  for (const int packed : {c.pp, c.pr, c.ps, c.pc}) require_type(v, packed, ply::Type::u32, "uint32", path);

  const ply::Element* sh = f.element("sh");
  int rest = 0;
  if (sh) {
    if (sh->count != v.count)
      throw SceneFileError(path, "element 'sh' has " + std::to_string(sh->count) + " rows but there are " +
                                     std::to_string(v.count) + " Gaussians");
    rest = count_rest(*sh, path);
    for (int j = 0; j < rest; ++j)
      require_type(*sh, sh->find("f_rest_" + std::to_string(j)), ply::Type::u8, "uint8", path);
  }
  GaussianModel m;
  m.sh_degree = degree_of_rest_count(rest);
  m.resize(v.count);
  for (int j = 0; j < rest; ++j) {
    c.rest_idx.push_back(sh->find("f_rest_" + std::to_string(j)));
    c.rest_slot.push_back(rest_slot(m.sh_coeffs(), j));
  }

  walk_rows(f, {&v, sh}, &chunk, v.count, options, progress, [&](uint64_t begin, uint64_t end) {
    float r[12], cr[6] = {0, 0, 0, 1, 1, 1};
    for (uint64_t i = begin; i < end; ++i) {
      if (i % 256 == 0) {  // blocks start at a chunk
        const uint64_t ci = i / 256;
        for (int k = 0; k < 12; ++k) r[k] = finite(f.value(chunk, ci, c.range_idx[k]), chunk, ci, c.range_idx[k], path);
        if (c.color_ranges)
          for (int k = 0; k < 6; ++k)
            cr[k] = finite(f.value(chunk, ci, c.color_idx[k]), chunk, ci, c.color_idx[k], path);
      }
      decode_compressed_row(f, v, sh, c, r, cr, i, m);
    }
  });
  return m;
}

GaussianModel load_ply(const std::string& path, const LoadOptions& options, const LoadProgress& progress) {
  const ply::File f = ply::read_file(path);
  const ply::Element* v = f.element("vertex");
  if (!v) throw SceneFileError(path, "no 'vertex' element");
  if (v->count == 0) throw SceneFileError(path, "the scene holds no Gaussians (vertex count 0)");
  if (v->count > (1ull << 31)) throw SceneFileError(path, "more than 2^31 Gaussians");
  const ply::Element* chunk = f.element("chunk");
  return (chunk && v->find("packed_position") >= 0) ? load_compressed(f, *chunk, *v, options, progress)
                                                    : load_inria(f, *v, options, progress);
}

}  // namespace

GaussianModel load_scene(const std::string& path, const LoadProgress& progress) {
  return load_scene(path, LoadOptions{}, progress);
}

GaussianModel load_scene(const std::string& path, const LoadOptions& options, const LoadProgress& progress) {
  GaussianModel m;
  switch (detect_scene_format(path)) {
    case SceneFormat::spz:
      m = read_spz(path, progress);
      break;
    case SceneFormat::splat:
      m = read_splat(path, progress);
      break;
    case SceneFormat::gltf:
      m = read_gltf(path, progress);
      break;
    case SceneFormat::sog:
      m = read_sog(path, progress);
      break;
    case SceneFormat::compact:
      m = read_compact_scene(path, progress, options.threads);
      break;
    case SceneFormat::ply:
      m = load_ply(path, options, progress);
      break;
  }
  m.name = scene_name(path);
  try {
    m.validate();
  } catch (const std::exception& e) {
    throw SceneFileError(path, e.what());
  }
  return m;
}

}  // namespace catgs
