#include "scene/format_detect.h"

#include <cctype>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <vector>

#include "scene/spz_file.h"

namespace catgs {

SceneFormat detect_scene_format(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<uint8_t> head(4, 0);
  in.read(reinterpret_cast<char*>(head.data()), 4);
  head.resize(static_cast<std::size_t>(in ? 4 : in.gcount()));
  if (head.size() == 4 && head[0] == 'p' && head[1] == 'l' && head[2] == 'y') return SceneFormat::ply;
  if (looks_like_spz(head)) return SceneFormat::spz;
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".splat") return SceneFormat::splat;
  return SceneFormat::ply;
}

}  // namespace catgs
