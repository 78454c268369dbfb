// VideoExport in a server built with -DCATGS_VIDEO_EXPORT=OFF (no libavformat; video_export.h):
// every export is refused with a reason the page shows.
#include <stdexcept>

#include "session/video_export.h"

namespace catgs::server {

bool video_export_built() { return false; }

struct VideoExport::Writer {};

VideoExport::~VideoExport() = default;

bool VideoExport::step() {
  throw std::runtime_error("video export not built (this server was built with -DCATGS_VIDEO_EXPORT=OFF)");
}

}  // namespace catgs::server
