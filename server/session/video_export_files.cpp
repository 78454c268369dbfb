// The export files' names and folder (video_export.h); built with and without video export.
#include <cstdio>
#include <filesystem>
#include <random>
#include <stdexcept>
#include <system_error>

#include "session/video_export.h"

namespace catgs::server {

namespace fs = std::filesystem;

namespace {

constexpr const char* kPrefix = "catgs-export-";

// 128 random bits in hex: another session cannot guess a file's name (and nothing serves the
// folder; the name only keeps concurrent exports apart and stale files recognisable).
std::string random_name() {
  std::random_device rd;
  std::string hex;
  for (int i = 0; i < 4; ++i) {
    char buf[9];
    std::snprintf(buf, sizeof buf, "%08x", static_cast<unsigned>(rd()));
    hex += buf;
  }
  return std::string(kPrefix) + hex + ".mp4";
}

}  // namespace

std::string export_folder(const std::string& dir) {
  std::error_code ec;
  const fs::path folder = dir.empty() ? fs::temp_directory_path(ec) / "catgs-exports" : fs::path(dir);
  fs::create_directories(folder, ec);
  if (ec || !fs::is_directory(folder))
    throw std::runtime_error("--export-dir " + folder.string() + ": cannot create the folder" +
                             (ec ? " (" + ec.message() + ")" : std::string()));
  return folder.string();
}

int remove_stale_exports(const std::string& folder) {
  int removed = 0;
  std::error_code ec;
  for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(kPrefix, 0) != 0 || it->path().extension() != ".mp4") continue;
    std::error_code rm;
    if (fs::remove(it->path(), rm)) ++removed;
  }
  return removed;
}

VideoExport::VideoExport(ExportPlan plan, std::shared_ptr<const GaussianModel> model, std::string renderer_kind,
                         RenderOptions options, int gpu, int encoder_threads, const std::string& folder)
    : plan_(std::move(plan)),
      model_(std::move(model)),
      renderer_kind_(std::move(renderer_kind)),
      options_(std::move(options)),
      gpu_(gpu),
      encoder_threads_(encoder_threads),
      path_((fs::path(folder) / random_name()).string()) {
  options_.pipeline = plan_.pipeline;
}

}  // namespace catgs::server
