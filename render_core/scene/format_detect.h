// Which reader a scene file needs, decided by its first bytes rather than its name: a file saved
// as .ply that is really .spz (or the reverse) still loads.
#pragma once

#include <string>

namespace catgs {

enum class SceneFormat {
  ply,      // starts with "ply\n": INRIA 3DGS PLY or SuperSplat compressed PLY (ply_io.h)
  spz,      // starts with "NGSP" (version 4) or the gzip magic 1f 8b (versions 1-3) (spz_file.h)
  gltf,     // starts with "glTF" (.glb) or is JSON naming KHR_gaussian_splatting (.gltf) (gltf_file.h)
  splat,    // no magic: antimatter15 .splat, recognised by its records (splat_file.h looks_like_splat)
            // or, where they do not pass, by its .splat extension (the reader then names the fault)
  compact,  // starts with "CATGSCMP": our compact scene (compact_file.h)
  sog,      // a zip archive ("PK\3\4", a bundled .sog) or JSON naming "means" and "files" (SOG's
            // meta.json) (sog_file.h)
};

// Reads the first bytes of `path`. Files with none of the magics above, no .splat records and no
// .splat extension are reported as ply, so that the PLY reader names what is wrong ("not a PLY
// file") and a missing file fails there with "cannot open file".
SceneFormat detect_scene_format(const std::string& path);

}  // namespace catgs
