// glTF 2.0 + KHR_gaussian_splatting reader (gltf_file.h), through tinygltf (Debian libtinygltf-dev).
#include "scene/gltf_file.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <cmath>
#include <cstring>
#include <functional>
#include <map>

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>

#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>

#include "scene/sh_rotation.h"

namespace catgs {
namespace {

constexpr const char* kExt = "KHR_gaussian_splatting";

// Skips images entirely: Gaussian scenes carry none, and we build tinygltf without stb_image.
bool ignore_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
  return true;
}

// Bytes of one component of glTF component type `t`; 0 for a type an attribute cannot have here.
std::size_t component_bytes(int t) {
  switch (t) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
      return 4;
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
      return 2;
    default:
      return 0;
  }
}

// One component at `p` as a float: floats as stored; integers (KHR_mesh_quantization) as the glTF
// 2.0 spec decodes them (section 3.11, "Animations", and 3.6.2.3 "normalized"): normalized
// signed c -> max(c / (2^(b-1) - 1), -1), unsigned c -> c / (2^b - 1); not normalized, c itself.
float component(const unsigned char* p, int type, bool normalized) {
  switch (type) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT: {
      float f;
      std::memcpy(&f, p, 4);
      return f;
    }
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      const auto c = static_cast<float>(static_cast<int8_t>(p[0]));
      return normalized ? std::max(c / 127.0f, -1.0f) : c;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return normalized ? p[0] / 255.0f : static_cast<float>(p[0]);
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      int16_t c;
      std::memcpy(&c, p, 2);
      return normalized ? std::max(static_cast<float>(c) / 32767.0f, -1.0f) : static_cast<float>(c);
    }
    default: {  // TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT
      uint16_t c;
      std::memcpy(&c, p, 2);
      return normalized ? static_cast<float>(c) / 65535.0f : static_cast<float>(c);
    }
  }
}

// One accessor of `type` (VEC3, ...) per element as floats, copied out densely (handles
// byteStride): float components, or 8- and 16-bit integers as KHR_mesh_quantization allows,
// dequantized (component).
std::vector<float> read_floats(const std::string& path, const tinygltf::Model& m, int index, const std::string& name,
                               int type, std::size_t count) {
  if (index < 0 || index >= static_cast<int>(m.accessors.size())) {
    throw SceneFileError(path, "attribute " + name + " names no accessor");
  }
  const tinygltf::Accessor& a = m.accessors[index];
  const std::size_t bytes = component_bytes(a.componentType);
  if (bytes == 0) {
    throw SceneFileError(path, "attribute " + name + " has component type " + std::to_string(a.componentType) +
                                   ", expected float (5126) or an 8- or 16-bit integer (5120-5123)");
  }
  if (a.type != type) {
    throw SceneFileError(path, "attribute " + name + " has the wrong accessor type");
  }
  if (a.count != count) {
    throw SceneFileError(path, "attribute " + name + " has " + std::to_string(a.count) + " elements, POSITION has " +
                                   std::to_string(count));
  }
  if (a.sparse.isSparse) throw SceneFileError(path, "attribute " + name + " is sparse (not supported)");
  const int comps = tinygltf::GetNumComponentsInType(type);
  // Bounds first, in arithmetic that cannot wrap, then the allocation: `count` comes from the
  // file. An accessor without a buffer view (all zeros in glTF) carries no Gaussians' data.
  if (a.bufferView < 0 || a.bufferView >= static_cast<int>(m.bufferViews.size())) {
    throw SceneFileError(path, "attribute " + name + " names no buffer view");
  }
  const tinygltf::BufferView& v = m.bufferViews[a.bufferView];
  if (v.buffer < 0 || v.buffer >= static_cast<int>(m.buffers.size())) {
    throw SceneFileError(path, "attribute " + name + " names no buffer");
  }
  const std::vector<unsigned char>& data = m.buffers[v.buffer].data;
  const std::size_t elem = bytes * static_cast<std::size_t>(comps);
  const std::size_t stride = v.byteStride ? v.byteStride : elem;
  const std::size_t start = v.byteOffset + a.byteOffset, end = v.byteOffset + v.byteLength;
  const bool fits = v.byteOffset <= data.size() && v.byteLength <= data.size() - v.byteOffset && start <= end &&
                    (count == 0 || (end - start >= elem && count - 1 <= (end - start - elem) / stride));
  if (!fits) throw SceneFileError(path, "attribute " + name + " runs past the end of its buffer");
  std::vector<float> out(count * static_cast<std::size_t>(comps), 0.0f);
  for (std::size_t i = 0; i < count; ++i)
    for (int c = 0; c < comps; ++c)
      out[i * comps + c] = component(data.data() + start + i * stride + c * bytes, a.componentType, a.normalized);
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (!std::isfinite(out[i])) {
      throw SceneFileError(path, "attribute " + name + " of Gaussian " + std::to_string(i / comps) + " is not finite");
    }
  }
  return out;
}

// A primitive to read, with its node's world transform (glTF axes).
struct Instance {
  const tinygltf::Primitive* primitive;
  glm::dmat4 world;
  int node;  // -1: no scene names it (a file without scenes)
};

// A node's local transform: its matrix (column-major) or translation * rotation * scale (glTF 2.0
// section 3.5.3, "Transformations").
glm::dmat4 local_transform(const tinygltf::Node& n) {
  if (n.matrix.size() == 16) return glm::make_mat4(n.matrix.data());
  glm::dmat4 t(1.0), r(1.0), s(1.0);
  if (n.translation.size() == 3) t = glm::translate(glm::dmat4(1.0), glm::make_vec3(n.translation.data()));
  if (n.rotation.size() == 4)  // (x, y, z, w)
    r = glm::mat4_cast(glm::normalize(glm::dquat(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2])));
  if (n.scale.size() == 3) s = glm::scale(glm::dmat4(1.0), glm::make_vec3(n.scale.data()));
  return t * r * s;
}

// The KHR_gaussian_splatting primitives the default scene draws, each with the product of its
// node's and ancestors' transforms; a file without scenes: every such primitive, untransformed.
std::vector<Instance> splat_instances(const std::string& path, const tinygltf::Model& m) {
  std::vector<Instance> out;
  auto add_mesh = [&](int mesh, const glm::dmat4& world, int node) {
    if (mesh < 0) return;
    if (mesh >= static_cast<int>(m.meshes.size())) throw SceneFileError(path, "node names no mesh");
    for (const tinygltf::Primitive& p : m.meshes[mesh].primitives)
      if (p.extensions.count(kExt)) out.push_back({&p, world, node});
  };
  if (m.scenes.empty()) {
    for (std::size_t i = 0; i < m.meshes.size(); ++i) add_mesh(static_cast<int>(i), glm::dmat4(1.0), -1);
    return out;
  }
  const int scene = m.defaultScene >= 0 ? m.defaultScene : 0;
  if (scene >= static_cast<int>(m.scenes.size())) throw SceneFileError(path, "the default scene does not exist");
  // Depth-first over the node tree; glTF forbids cycles, and a file that has one is refused.
  std::vector<bool> on_path(m.nodes.size(), false);
  std::function<void(int, const glm::dmat4&)> visit = [&](int node, const glm::dmat4& parent) {
    if (node < 0 || node >= static_cast<int>(m.nodes.size()))
      throw SceneFileError(path, "a scene or node names node " + std::to_string(node) + ", which does not exist");
    if (on_path[node]) throw SceneFileError(path, "node " + std::to_string(node) + " is its own ancestor");
    on_path[node] = true;
    const tinygltf::Node& n = m.nodes[node];
    const glm::dmat4 world = parent * local_transform(n);
    add_mesh(n.mesh, world, node);
    for (int child : n.children) visit(child, world);
    on_path[node] = false;
  };
  for (int root : m.scenes[scene].nodes) visit(root, glm::dmat4(1.0));
  return out;
}

// glTF axes -> ours (header): 180 degrees about z, its own inverse.
const glm::dmat4 kFlip =
    glm::dmat4(glm::dvec4(-1, 0, 0, 0), glm::dvec4(0, -1, 0, 0), glm::dvec4(0, 0, 1, 0), glm::dvec4(0, 0, 0, 1));

// Applies a node's world transform (glTF axes) to Gaussians [begin, end) of `model` (our axes):
// the same transform in our axes, flip * world * flip. A Gaussian stays a Gaussian under a
// similarity (rotation, uniform scale, translation): centres move, rotations compose, log
// scales add log s, SH coefficients rotate with it (sh_rotation.h). Shear, non-uniform scale and
// reflections would need each covariance refactored and the SH mirrored: refused.
void apply_transform(const std::string& path, const Instance& inst, GaussianModel& model, std::size_t begin,
                     std::size_t end) {
  const glm::dmat4 M = kFlip * inst.world * kFlip;
  if (M == glm::dmat4(1.0)) return;
  const glm::dmat3 A(M);
  const double det = glm::determinant(A);
  const double s = std::cbrt(det);
  const glm::dmat3 R = A / (s != 0.0 ? s : 1.0);
  const glm::dmat3 err = glm::transpose(R) * R - glm::dmat3(1.0);
  double worst = 0;
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r) worst = std::max(worst, std::abs(err[c][r]));
  const glm::dvec4 last_row(M[0][3], M[1][3], M[2][3], M[3][3]);
  if (!(det > 0.0) || !(worst < 1e-5) || last_row != glm::dvec4(0, 0, 0, 1)) {
    throw SceneFileError(path, "node " + std::to_string(inst.node) +
                                   ": only rotation, uniform scale and translation are supported in a transform "
                                   "(this one has shear, non-uniform scale, a reflection or a projection)");
  }
  const glm::quat q_r(glm::quat_cast(glm::mat3(R)));
  const glm::vec3 t(M[3]);
  const auto log_s = static_cast<float>(std::log(s));
  const ShRotation sh_r = make_sh_rotation(model.sh_degree, glm::mat3(R));
  const std::size_t k3 = static_cast<std::size_t>(model.sh_coeffs()) * 3;
  for (std::size_t i = begin; i < end; ++i) {
    const glm::dvec3 p(model.means[3 * i], model.means[3 * i + 1], model.means[3 * i + 2]);
    const glm::vec3 p2(A * p + glm::dvec3(t));
    const glm::quat q(model.rotations[4 * i], model.rotations[4 * i + 1], model.rotations[4 * i + 2],
                      model.rotations[4 * i + 3]);  // (w, x, y, z)
    const glm::quat q2 = q_r * q;
    for (int a = 0; a < 3; ++a) {
      model.means[3 * i + a] = p2[a];
      model.log_scales[3 * i + a] += log_s;
    }
    model.rotations[4 * i] = q2.w;
    model.rotations[4 * i + 1] = q2.x;
    model.rotations[4 * i + 2] = q2.y;
    model.rotations[4 * i + 3] = q2.z;
    sh_r.apply(&model.sh[i * k3]);
  }
}

// Attribute `name` of `prim` (an accessor index); throws naming it when missing.
int attribute(const std::string& path, const tinygltf::Primitive& prim, const std::string& name) {
  auto it = prim.attributes.find(name);
  if (it == prim.attributes.end()) throw SceneFileError(path, "missing attribute " + name);
  return it->second;
}

// The SH degree `prim` carries: the highest l with SH_DEGREE_l_COEF_0 (and every lower one).
int primitive_sh_degree(const std::string& path, const tinygltf::Primitive& prim) {
  const std::string p = std::string(kExt) + ":";
  int degree = -1;
  for (int l = 0; l <= kMaxShDegree; ++l) {
    const bool has = prim.attributes.count(p + "SH_DEGREE_" + std::to_string(l) + "_COEF_0") > 0;
    if (!has) break;
    degree = l;
  }
  if (degree < 0) throw SceneFileError(path, "missing attribute " + p + "SH_DEGREE_0_COEF_0");
  return degree;
}

std::size_t primitive_count(const std::string& path, const tinygltf::Model& m, const tinygltf::Primitive& prim) {
  const int pos_index = attribute(path, prim, "POSITION");
  if (pos_index < 0 || pos_index >= static_cast<int>(m.accessors.size())) {
    throw SceneFileError(path, "attribute POSITION names no accessor");
  }
  return m.accessors[pos_index].count;
}

// Reads `prim`'s n Gaussians into model rows [at, at + n), in our axes (header); SH bands the
// primitive lacks (the model's degree is the highest of any primitive's) stay zero.
void read_primitive(const std::string& path, const tinygltf::Model& m, const tinygltf::Primitive& prim,
                    GaussianModel& model, std::size_t at, std::size_t n) {
  const std::string p = std::string(kExt) + ":";
  auto attr = [&](const std::string& name) { return attribute(path, prim, name); };
  const std::vector<float> pos = read_floats(path, m, attr("POSITION"), "POSITION", TINYGLTF_TYPE_VEC3, n);
  const std::vector<float> rot = read_floats(path, m, attr(p + "ROTATION"), p + "ROTATION", TINYGLTF_TYPE_VEC4, n);
  const std::vector<float> scl = read_floats(path, m, attr(p + "SCALE"), p + "SCALE", TINYGLTF_TYPE_VEC3, n);
  const std::vector<float> opa = read_floats(path, m, attr(p + "OPACITY"), p + "OPACITY", TINYGLTF_TYPE_SCALAR, n);
  const int degree = primitive_sh_degree(path, prim);
  const int k_count = model.sh_coeffs();
  for (std::size_t j = 0; j < n; ++j) {
    const std::size_t i = at + j;
    // 180 degrees about z (header): (x, y, z) -> (-x, -y, z).
    model.means[i * 3 + 0] = -pos[j * 3 + 0];
    model.means[i * 3 + 1] = -pos[j * 3 + 1];
    model.means[i * 3 + 2] = pos[j * 3 + 2];
    // q = -(0, 0, 0, 1) * q_glTF for q_glTF = (x, y, z, w): (w, x, y, z) = (z, y, -x, -w).
    const float qx = rot[j * 4 + 0], qy = rot[j * 4 + 1], qz = rot[j * 4 + 2], qw = rot[j * 4 + 3];
    model.rotations[i * 4 + 0] = qz;
    model.rotations[i * 4 + 1] = qy;
    model.rotations[i * 4 + 2] = -qx;
    model.rotations[i * 4 + 3] = -qw;
    for (int c = 0; c < 3; ++c) {
      const float s = scl[j * 3 + c];
      model.log_scales[i * 3 + c] = s > 0.0f ? std::log(s) : -kOpacityLogitLimit;
    }
    const float a = opa[j];
    model.opacity_logits[i] = a <= 0.0f ? -kOpacityLogitLimit
                              : a >= 1.0f
                                  ? kOpacityLogitLimit
                                  : std::clamp(std::log(a / (1.0f - a)), -kOpacityLogitLimit, kOpacityLogitLimit);
  }
  for (int l = 0; l <= degree; ++l) {
    for (int c = 0; c <= 2 * l; ++c) {
      const std::string name = p + "SH_DEGREE_" + std::to_string(l) + "_COEF_" + std::to_string(c);
      const std::vector<float> coef = read_floats(path, m, attr(name), name, TINYGLTF_TYPE_VEC3, n);
      const int k = l * l + c;
      const float sign = ((c - l) % 2 != 0) ? -1.0f : 1.0f;  // odd order m = c - l flips under z by 180
      for (std::size_t j = 0; j < n; ++j) {
        for (int ch = 0; ch < 3; ++ch) model.sh[((at + j) * k_count + k) * 3 + ch] = sign * coef[j * 3 + ch];
      }
    }
  }
}

}  // namespace

bool looks_like_gltf(const std::vector<uint8_t>& head) {
  if (head.size() >= 4 && std::memcmp(head.data(), "glTF", 4) == 0) return true;
  auto first = std::find_if(head.begin(), head.end(), [](uint8_t c) { return !std::isspace(c); });
  if (first == head.end() || *first != '{') return false;
  const std::string text(head.begin(), head.end());
  return text.find(kExt) != std::string::npos;
}

GaussianModel read_gltf(const std::string& path, const LoadProgress& progress) {
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(ignore_image, nullptr);
  tinygltf::Model m;
  std::string err;
  std::string warn;
  std::vector<uint8_t> head(4, 0);
  {
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) throw SceneFileError(path, "cannot open file");
    head.resize(std::fread(head.data(), 1, head.size(), f));
    std::fclose(f);
  }
  const bool binary = head.size() == 4 && std::memcmp(head.data(), "glTF", 4) == 0;
  const bool ok =
      binary ? loader.LoadBinaryFromFile(&m, &err, &warn, path) : loader.LoadASCIIFromFile(&m, &err, &warn, path);
  if (!ok) throw SceneFileError(path, "not valid glTF: " + err);

  const std::vector<Instance> instances = splat_instances(path, m);
  if (instances.empty()) throw SceneFileError(path, "no mesh primitive with the KHR_gaussian_splatting extension");
  // Each Gaussian takes bytes of some buffer, so the buffers' size bounds the total before the
  // model is allocated (each attribute's own bounds are checked as it is read).
  std::size_t buffer_bytes = 0;
  for (const tinygltf::Buffer& b : m.buffers) buffer_bytes += b.data.size();
  std::vector<std::size_t> counts;
  std::size_t n = 0;
  int degree = 0;
  for (const Instance& inst : instances) {
    counts.push_back(primitive_count(path, m, *inst.primitive));
    if (counts.back() > buffer_bytes - std::min(n, buffer_bytes))
      throw SceneFileError(path, "more Gaussians declared than the buffers hold");
    n += counts.back();
    degree = std::max(degree, primitive_sh_degree(path, *inst.primitive));
  }

  GaussianModel model;
  model.name = std::filesystem::path(path).stem().string();
  model.sh_degree = degree;
  model.resize(n);
  std::size_t at = 0;
  for (std::size_t k = 0; k < instances.size(); ++k) {
    read_primitive(path, m, *instances[k].primitive, model, at, counts[k]);
    apply_transform(path, instances[k], model, at, at + counts[k]);
    at += counts[k];
    if (progress) progress(at, n);  // after each primitive; the last is (n, n)
  }
  return model;
}

}  // namespace catgs
