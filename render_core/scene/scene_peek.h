// What can be said about a scene file without loading it (issue 20: GET /scenes lists scenes that
// load on first use): the header only (PLY: the text up to end_header; .splat: the file size),
// never the Gaussians, so listing many large scenes costs neither time nor memory. Bounds need
// every mean and are never here.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

namespace catgs {

struct ScenePeek {
  std::string name;    // scene_name(path)
  std::string format;  // "ply", "compressed_ply", "spz", "splat" or "gltf" (by the file's first bytes)
  // Gaussians in the file: PLY (the vertex element's count), .splat (file size / 32); unknown for
  // .spz (gzip-compressed header) and glTF (accessor counts inside the JSON / binary chunk).
  std::optional<std::uint64_t> gaussians;
  std::optional<int> sh_degree;  // PLY (from the f_rest_* count), .splat (0); unknown otherwise
};

// Reads the format and what the header says. Throws SceneFileError naming `path` when the file
// cannot be opened, or a PLY file has no end_header in its first 64 KiB, a vertex count that is
// not a number or an f_rest_* count that matches no SH degree. A header that passes may still fail
// to load (truncated rows, bad values): only load_scene reads those.
ScenePeek peek_scene(const std::string& path);

// The scene's name: the file name without its scene extension (.compressed.ply, .ply, .spz,
// .splat, .glb, .gltf), as load_scene sets GaussianModel::name.
std::string scene_name(const std::string& path);

}  // namespace catgs
