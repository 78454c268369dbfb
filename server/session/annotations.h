// A scene's annotations (issue 38): hotspots (labelled points with an optional view), the hotspot
// tour and the measurement scale, kept as a small JSON file beside the scene and sent to every
// session after Welcome (proto Annotations); authors save it with SaveAnnotations.
//
// File: the scene's path with its extension replaced by ".hotspots.json" (biker.ply ->
// biker.hotspots.json, city.compressed.ply -> city.compressed.hotspots.json), UTF-8, at most
// 32 KiB:
//   {
//     "version": 1,
//     "metres_per_unit": 0.42,            optional, > 0: one scene unit in metres (measurements)
//     "hotspots": [                       at most 200
//       { "id": "seat",                   1..64 bytes, unique
//         "title": "The seat",            1..120 bytes
//         "text": "Leather, 1970s",       0..2000 bytes (optional)
//         "position": [x, y, z],          world units, the scene file's frame
//         "view": {                       optional: where clicking the hotspot flies to
//           "position": [x, y, z],        camera centre, world units
//           "orientation": [w, x, y, z],  camera-to-world quaternion, OpenCV axes (as Pose)
//           "fov": 50 } } ],              vertical field of view, degrees, in (1, 170)
//     "tour": ["seat", ...]               optional: hotspot ids a tour steps through, in order
//   }
// Every number must be finite and within +-1e30 (as Pose). Keys not listed are dropped when the
// file is read or saved (what is sent and written is the normalised form).
//
// Errors: a file that is missing is no error (no annotations); one that is unreadable, too large,
// not JSON or not of this form gives an error naming the file and what is wrong, sent in
// Annotations.error and logged, and the scene opens without annotations.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace catgs::server {

inline constexpr std::size_t kMaxAnnotationsBytes = 32 * 1024;
inline constexpr std::size_t kMaxHotspots = 200;
inline constexpr std::size_t kMaxHotspotIdBytes = 64;
inline constexpr std::size_t kMaxHotspotTitleBytes = 120;
inline constexpr std::size_t kMaxHotspotTextBytes = 2000;

// <scene path without its extension>.hotspots.json (a scene folder's meta.json -> meta.hotspots.json).
std::string annotations_path(const std::string& scene_path);

// Validates annotations JSON and returns its normalised, compact serialisation. Throws
// std::invalid_argument "SOURCE: what is wrong" (the JSON path of the bad value, e.g.
// "hotspots[2].position: expected 3 numbers").
std::string normalise_annotations(std::string_view text, const std::string& source);

// What read_annotations found: json "" and error "" when the scene has no annotations file.
struct AnnotationsFile {
  std::string json;   // normalised
  std::string error;  // "FILE: what is wrong"; json is "" then
};
AnnotationsFile read_annotations(const std::string& scene_path);

// Validates `text` and writes its normalised form to annotations_path(scene_path) through a
// temporary file renamed over it (a reader never sees half a file). Returns the normalised JSON.
// Throws std::invalid_argument (invalid; nothing written) or std::runtime_error (the write
// failed), both naming the file.
std::string write_annotations(const std::string& scene_path, std::string_view text);

}  // namespace catgs::server
