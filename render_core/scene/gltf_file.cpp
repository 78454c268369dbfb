// glTF 2.0 + KHR_gaussian_splatting reader (gltf_file.h), through tinygltf (Debian libtinygltf-dev).
#include "scene/gltf_file.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <cmath>
#include <cstring>
#include <map>

#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>

namespace catgs {
namespace {

constexpr const char* kExt = "KHR_gaussian_splatting";

// Skips images entirely: Gaussian scenes carry none, and we build tinygltf without stb_image.
bool ignore_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
  return true;
}

// One float accessor of `components` per element, copied out densely (handles byteStride).
std::vector<float> read_floats(const std::string& path, const tinygltf::Model& m, int index, const std::string& name,
                               int type, std::size_t count) {
  if (index < 0 || index >= static_cast<int>(m.accessors.size())) {
    throw SceneFileError(path, "attribute " + name + " names no accessor");
  }
  const tinygltf::Accessor& a = m.accessors[index];
  if (a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT) {
    throw SceneFileError(path, "attribute " + name + " has component type " + std::to_string(a.componentType) +
                                   ", expected float (5126)");
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
  const std::size_t elem = sizeof(float) * static_cast<std::size_t>(comps);
  const std::size_t stride = v.byteStride ? v.byteStride : elem;
  const std::size_t start = v.byteOffset + a.byteOffset, end = v.byteOffset + v.byteLength;
  const bool fits = v.byteOffset <= data.size() && v.byteLength <= data.size() - v.byteOffset && start <= end &&
                    (count == 0 || (end - start >= elem && count - 1 <= (end - start - elem) / stride));
  if (!fits) throw SceneFileError(path, "attribute " + name + " runs past the end of its buffer");
  std::vector<float> out(count * static_cast<std::size_t>(comps), 0.0f);
  for (std::size_t i = 0; i < count; ++i) std::memcpy(&out[i * comps], data.data() + start + i * stride, elem);
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (!std::isfinite(out[i])) {
      throw SceneFileError(path, "attribute " + name + " of Gaussian " + std::to_string(i / comps) + " is not finite");
    }
  }
  return out;
}

}  // namespace

bool looks_like_gltf(const std::vector<uint8_t>& head) {
  if (head.size() >= 4 && std::memcmp(head.data(), "glTF", 4) == 0) return true;
  auto first = std::find_if(head.begin(), head.end(), [](uint8_t c) { return !std::isspace(c); });
  if (first == head.end() || *first != '{') return false;
  const std::string text(head.begin(), head.end());
  return text.find(kExt) != std::string::npos;
}

GaussianModel read_gltf(const std::string& path) {
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

  const tinygltf::Primitive* prim = nullptr;
  for (const tinygltf::Mesh& mesh : m.meshes) {
    for (const tinygltf::Primitive& p : mesh.primitives) {
      if (p.extensions.count(kExt)) {
        if (prim) throw SceneFileError(path, "more than one KHR_gaussian_splatting primitive (not supported)");
        prim = &p;
      }
    }
  }
  if (!prim) throw SceneFileError(path, "no mesh primitive with the KHR_gaussian_splatting extension");

  auto attr = [&](const std::string& name) {
    auto it = prim->attributes.find(name);
    if (it == prim->attributes.end()) throw SceneFileError(path, "missing attribute " + name);
    return it->second;
  };
  const int pos_index = attr("POSITION");
  if (pos_index < 0 || pos_index >= static_cast<int>(m.accessors.size())) {
    throw SceneFileError(path, "attribute POSITION names no accessor");
  }
  const std::size_t n = m.accessors[pos_index].count;
  const std::string p = std::string(kExt) + ":";
  const std::vector<float> pos = read_floats(path, m, pos_index, "POSITION", TINYGLTF_TYPE_VEC3, n);
  const std::vector<float> rot = read_floats(path, m, attr(p + "ROTATION"), p + "ROTATION", TINYGLTF_TYPE_VEC4, n);
  const std::vector<float> scl = read_floats(path, m, attr(p + "SCALE"), p + "SCALE", TINYGLTF_TYPE_VEC3, n);
  const std::vector<float> opa = read_floats(path, m, attr(p + "OPACITY"), p + "OPACITY", TINYGLTF_TYPE_SCALAR, n);

  int degree = -1;
  for (int l = 0; l <= kMaxShDegree; ++l) {
    const bool has = prim->attributes.count(p + "SH_DEGREE_" + std::to_string(l) + "_COEF_0") > 0;
    if (!has) break;
    degree = l;
  }
  if (degree < 0) throw SceneFileError(path, "missing attribute " + p + "SH_DEGREE_0_COEF_0");

  GaussianModel model;
  model.name = std::filesystem::path(path).stem().string();
  model.sh_degree = degree;
  model.resize(n);
  const int k_count = model.sh_coeffs();
  for (std::size_t i = 0; i < n; ++i) {
    // 180 degrees about z (header): (x, y, z) -> (-x, -y, z).
    model.means[i * 3 + 0] = -pos[i * 3 + 0];
    model.means[i * 3 + 1] = -pos[i * 3 + 1];
    model.means[i * 3 + 2] = pos[i * 3 + 2];
    // q = -(0, 0, 0, 1) * q_glTF for q_glTF = (x, y, z, w): (w, x, y, z) = (z, y, -x, -w).
    const float qx = rot[i * 4 + 0], qy = rot[i * 4 + 1], qz = rot[i * 4 + 2], qw = rot[i * 4 + 3];
    model.rotations[i * 4 + 0] = qz;
    model.rotations[i * 4 + 1] = qy;
    model.rotations[i * 4 + 2] = -qx;
    model.rotations[i * 4 + 3] = -qw;
    for (int c = 0; c < 3; ++c) {
      const float s = scl[i * 3 + c];
      model.log_scales[i * 3 + c] = s > 0.0f ? std::log(s) : -kOpacityLogitLimit;
    }
    const float a = opa[i];
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
      for (std::size_t i = 0; i < n; ++i) {
        for (int ch = 0; ch < 3; ++ch) model.sh[(i * k_count + k) * 3 + ch] = sign * coef[i * 3 + ch];
      }
    }
  }
  return model;
}

}  // namespace catgs
