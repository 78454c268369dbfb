// VideoExport's rendering (video_export.h): a server built with CATGS_VIDEO_EXPORT (libavformat).
#include <filesystem>

#include "encode/tour_video.h"
#include "session/video_export.h"

namespace catgs::server {

bool video_export_built() { return true; }

struct VideoExport::Writer {
  std::unique_ptr<Renderer> renderer;
  std::unique_ptr<TourVideo> video;
};

VideoExport::~VideoExport() {
  writer_.reset();  // closes the file before it goes
  std::error_code ec;
  std::filesystem::remove(path_, ec);
}

bool VideoExport::step() {
  if (cancelled_) return false;
  if (!writer_) {
    auto w = std::make_shared<Writer>();
    w->renderer = make_renderer(renderer_kind_, model_, options_, nullptr, gpu_);
    TourVideoOptions o;
    o.path = path_;
    o.width = plan_.width;
    o.height = plan_.height;
    o.fps = plan_.fps;
    o.threads = encoder_threads_;  // a share of the cores: live sessions encode too
    w->video = std::make_unique<TourVideo>(o);
    writer_ = std::move(w);
  }
  const int k = frames_done_;
  writer_->video->add_frame(*writer_->renderer, plan_.frames[static_cast<std::size_t>(k)]);
  frames_done_ = k + 1;
  if (k + 1 < frames_total()) return false;
  writer_->video->finish();
  writer_->renderer.reset();  // its scene copy and buffers go now, not when the file is sent
  return true;
}

}  // namespace catgs::server
