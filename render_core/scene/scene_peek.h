// What can be said about a scene file without loading it (issue 20: GET /scenes lists scenes that
// load on first use): the header only (PLY: the text up to end_header; .splat: the file size; SOG:
// meta.json), never the Gaussians, so listing many large scenes costs neither time nor memory.
// Bounds need every mean and are never here.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

namespace catgs {

struct ScenePeek {
  std::string name;    // scene_name(path)
  std::string format;  // "ply", "compressed_ply", "spz", "splat", "gltf", "sog" or "catgs" (by content)
  // Gaussians in the file: PLY (the vertex element's count), .splat (file size / 32), SOG
  // (meta.json's count), compact (its header's, merged levels included); unknown for .spz (gzip-compressed header) and glTF (accessor counts
  // inside the JSON / binary chunk).
  std::optional<std::uint64_t> gaussians;
  // PLY (from the f_rest_* count), .splat (0), compact (its header), SOG (meta.json's shN bands; unknown for a version 1
  // file with SH, whose degree is the centroid image's width); unknown otherwise.
  std::optional<int> sh_degree;
};

// Reads the format and what the header says. Throws SceneFileError naming `path` when the file
// cannot be opened, or a PLY file has no end_header in its first 64 KiB, a vertex count that is
// not a number or an f_rest_* count that matches no SH degree, or a SOG scene's meta.json cannot
// be read (peek_sog, which also throws in a build without SOG support). A header that passes may
// still fail to load (truncated rows, bad values): only load_scene reads those.
ScenePeek peek_scene(const std::string& path);

// The scene's name: the file name without its scene extension (.compressed.ply, .ply, .spz,
// .splat, .glb, .gltf, .sog, .catgs), or the folder's name for an unbundled SOG's meta.json, as load_scene
// sets GaussianModel::name.
std::string scene_name(const std::string& path);

}  // namespace catgs
