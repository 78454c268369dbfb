#include "scene/format_detect.h"

#include <cctype>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <vector>

#include "scene/compact_file.h"
#include "scene/gltf_file.h"
#include "scene/sog_file.h"
#include "scene/splat_file.h"
#include "scene/spz_file.h"

namespace catgs {

SceneFormat detect_scene_format(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  // 4 KiB: enough for a .gltf's JSON to name its extension before the accessors.
  std::vector<uint8_t> head(4096, 0);
  in.read(reinterpret_cast<char*>(head.data()), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<std::size_t>(in.gcount()));
  if (head.size() >= 4 && head[0] == 'p' && head[1] == 'l' && head[2] == 'y') return SceneFormat::ply;
  if (looks_like_spz(head)) return SceneFormat::spz;
  if (looks_like_compact(head)) return SceneFormat::compact;
  if (looks_like_gltf(head)) return SceneFormat::gltf;
  if (looks_like_sog_zip(head) || looks_like_sog_meta(head)) return SceneFormat::sog;
  std::error_code ec;
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (!ec && looks_like_splat(head, size)) return SceneFormat::splat;
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".splat") return SceneFormat::splat;  // its reader names what is wrong
  // A .gltf's JSON may name its extension only past the first 4 KiB (a writer that puts a
  // data-URI buffer first): its name decides, and tinygltf names what is wrong.
  if (ext == ".gltf") return SceneFormat::gltf;
  return SceneFormat::ply;
}

}  // namespace catgs
