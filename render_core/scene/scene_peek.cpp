// Scene headers without the Gaussians (scene_peek.h).
#include "scene/scene_peek.h"

#include <filesystem>
#include <fstream>
#include <sstream>

#include "scene/compact_file.h"
#include "scene/format_detect.h"
#include "scene/gaussian_model.h"
#include "scene/sog_file.h"

namespace catgs {

namespace {

constexpr std::size_t kMaxPlyHeader = 64 * 1024;
constexpr std::uint64_t kSplatRowBytes = 32;  // antimatter15 .splat: one 32-byte row a Gaussian

void peek_ply(const std::string& path, ScenePeek& out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneFileError(path, "cannot open file");
  std::string header(kMaxPlyHeader, '\0');
  in.read(header.data(), static_cast<std::streamsize>(header.size()));
  header.resize(static_cast<std::size_t>(in.gcount()));
  const std::size_t end = header.find("end_header");
  if (end == std::string::npos) throw SceneFileError(path, "no end_header in the first 64 KiB (not a PLY header)");
  std::istringstream lines(header.substr(0, end));
  std::string line, element;
  int rest = 0;
  bool chunks = false, packed = false;
  for (std::string word; std::getline(lines, line);) {
    std::istringstream words(line);
    words >> word;
    if (word == "element") {
      std::string count;
      words >> element >> count;
      if (element == "chunk") chunks = true;
      if (element != "vertex") continue;
      if (count.empty() || count.find_first_not_of("0123456789") != std::string::npos || count.size() > 19)
        throw SceneFileError(path, "element vertex count '" + count + "' is not a number");
      out.gaussians = std::stoull(count);
    } else if (word == "property") {
      std::string type, name;
      words >> type >> name;
      if (name.rfind("f_rest_", 0) == 0) ++rest;
      if (element == "vertex" && name.rfind("packed_", 0) == 0) packed = true;
    }
  }
  out.format = chunks && packed ? "compressed_ply" : "ply";
  for (int d = 0; d <= kMaxShDegree; ++d)
    if (3 * (sh_coeff_count(d) - 1) == rest) out.sh_degree = d;
  if (!out.sh_degree)
    throw SceneFileError(path, std::to_string(rest) + " f_rest properties match no SH degree (0, 9, 24 or 45)");
}

}  // namespace

std::string scene_name(const std::string& path) {
  const std::filesystem::path p(path);
  std::string name = p.filename().string();
  // An unbundled SOG scene is a folder: meta.json says nothing of the scene.
  if (name == "meta.json" && p.parent_path().has_filename()) return p.parent_path().filename().string();
  for (const char* suffix : {".compressed.ply", ".ply", ".spz", ".splat", ".glb", ".gltf", ".sog", ".catgs"}) {
    const std::string s = suffix;
    if (name.size() > s.size() && name.compare(name.size() - s.size(), s.size(), s) == 0) {
      name.resize(name.size() - s.size());
      break;
    }
  }
  return name;
}

ScenePeek peek_scene(const std::string& path) {
  ScenePeek out;
  out.name = scene_name(path);
  switch (detect_scene_format(path)) {
    case SceneFormat::ply:
      peek_ply(path, out);
      break;
    case SceneFormat::spz:
      out.format = "spz";
      break;
    case SceneFormat::compact: {
      const CompactSummary c = peek_compact(path);
      out.format = "catgs";
      out.gaussians = c.gaussians;
      out.sh_degree = c.sh_degree;
      break;
    }
    case SceneFormat::gltf:
      out.format = "gltf";
      break;
    case SceneFormat::sog: {
      const SogSummary sog = peek_sog(path);
      out.format = "sog";
      out.gaussians = sog.gaussians;
      out.sh_degree = sog.sh_degree;
      break;
    }
    case SceneFormat::splat: {
      std::error_code ec;
      const std::uint64_t size = std::filesystem::file_size(path, ec);
      if (ec) throw SceneFileError(path, "cannot open file: " + ec.message());
      out.format = "splat";
      out.gaussians = size / kSplatRowBytes;
      out.sh_degree = 0;
      break;
    }
  }
  return out;
}

}  // namespace catgs
