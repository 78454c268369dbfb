#include "video/tour_video.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/progress.h"
#include "encode/h264_level.h"
#include "encode/x264_encoder.h"

namespace catgs::tools {

TourVideo::TourVideo(const TourVideoOptions& options) : options_(options) {
  const std::string size = std::to_string(options.width) + "x" + std::to_string(options.height);
  if (options.width <= 0 || options.height <= 0 || options.width % 2 || options.height % 2)
    throw std::invalid_argument("video size " + size + ": width and height must be even and positive (4:2:0)");
  if (options.fps <= 0 || options.fps > 240) throw std::invalid_argument("--fps must be in 1..240");
  if (options.crf < 0 || options.crf > 51) throw std::invalid_argument("--crf must be in 0..51");
  server::h264_level(options.width, options.height, options.fps);  // throws past level 6.2
  server::EncoderConfig config;
  config.width = options.width;
  config.height = options.height;
  config.fps = options.fps;
  config.crf = options.crf;  // crf alone: a file has no VBV to keep
  config.x264_preset = options.preset;
  config.global_header = true;
  encoder_ = std::make_unique<server::X264Encoder>(config);
  file_ = std::make_unique<server::Mp4File>(options.path, options.width, options.height, options.fps,
                                            encoder_->extradata());
}

void TourVideo::render(Renderer& renderer, const Trace& frames, std::FILE* progress, bool progress_tty) {
  if (frames.empty()) throw std::invalid_argument(options_.path + ": no frames to render");
  const long keyframe_every = std::max(1L, std::lround(options_.keyframe_seconds * options_.fps));
  std::unique_ptr<Progress> meter;
  if (progress) meter = std::make_unique<Progress>(progress, progress_tty, static_cast<long>(frames.size()), "frames");
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const Camera& camera = frames[k].camera;
    if (camera.width != options_.width || camera.height != options_.height)
      throw std::invalid_argument("frame " + std::to_string(k) + " is " + std::to_string(camera.width) + "x" +
                                  std::to_string(camera.height) + ", the video " + std::to_string(options_.width) +
                                  "x" + std::to_string(options_.height));
    renderer.render_yuv420_at(camera, frames[k].time_s, encoder_->input_target());
    file_->write(encoder_->encode_input(static_cast<long>(k) % keyframe_every == 0));
    if (meter) meter->update(static_cast<long>(k + 1));
  }
  file_->finish();
}

}  // namespace catgs::tools
