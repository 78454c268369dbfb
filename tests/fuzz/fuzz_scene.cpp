// Fuzz target: any bytes as a scene file (the format detected by content, as load_scene does),
// then, for a scene that loads and is small, a render of it at 16 x 16 by the CPU core (exact
// pipeline, a camera looking at the scene's bounds). A SceneFileError is the expected answer to
// bad bytes; anything else (a crash, a sanitizer report, another exception) is a finding.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>

#include "render_small.h"
#include "scene/ply_io.h"

namespace {

// The scene file of this process (load_scene reads a path).
const std::string& scratch_path() {
  static const std::string path = "/tmp/catgs-fuzz-scene-" + std::to_string(::getpid()) + ".bin";
  return path;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  {
    std::FILE* f = std::fopen(scratch_path().c_str(), "wb");
    if (!f) return 0;
    if (size > 0) std::fwrite(data, 1, size, f);
    std::fclose(f);
  }
  try {
    auto model = std::make_shared<const catgs::GaussianModel>(catgs::load_scene(scratch_path()));
    if (model->size() <= 4096) {
      catgs::RenderOptions options;
      options.pipeline = catgs::Pipeline::exact;
      catgs::Image image;
      catgs::fuzz::render_small(model, options, image);
    }
  } catch (const catgs::SceneFileError&) {
    // The loader's answer to bad bytes: a clear error naming the file.
  } catch (const std::length_error&) {
    // The render budget's answer to a scene whose render list would not fit (renderer.h).
  }
  return 0;
}
