#include "encode/tour_video.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "encode/h264_level.h"
#include "encode/x264_encoder.h"

namespace catgs::server {

TourVideo::TourVideo(const TourVideoOptions& options) : options_(options) {
  const std::string size = std::to_string(options.width) + "x" + std::to_string(options.height);
  if (options.width <= 0 || options.height <= 0 || options.width % 2 || options.height % 2)
    throw std::invalid_argument("video size " + size + ": width and height must be even and positive (4:2:0)");
  if (options.fps <= 0 || options.fps > 240) throw std::invalid_argument("--fps must be in 1..240");
  if (options.crf < 0 || options.crf > 51) throw std::invalid_argument("--crf must be in 0..51");
  h264_level(options.width, options.height, options.fps);  // throws past level 6.2
  keyframe_every_ = std::max(1L, std::lround(options.keyframe_seconds * options.fps));
  EncoderConfig config;
  config.width = options.width;
  config.height = options.height;
  config.fps = options.fps;
  config.crf = options.crf;  // crf alone: a file has no VBV to keep
  config.x264_preset = options.preset;
  config.threads = options.threads;
  config.global_header = true;
  encoder_ = std::make_unique<X264Encoder>(config);
  file_ = std::make_unique<Mp4File>(options.path, options.width, options.height, options.fps, encoder_->extradata());
}

void TourVideo::add_frame(Renderer& renderer, const TimedCamera& frame) {
  const Camera& camera = frame.camera;
  if (camera.width != options_.width || camera.height != options_.height)
    throw std::invalid_argument("frame " + std::to_string(frames_) + " is " + std::to_string(camera.width) + "x" +
                                std::to_string(camera.height) + ", the video " + std::to_string(options_.width) + "x" +
                                std::to_string(options_.height));
  renderer.render_yuv420_at(camera, frame.time_s, encoder_->input_target());
  file_->write(encoder_->encode_input(frames_ % keyframe_every_ == 0));
  ++frames_;
}

void TourVideo::finish() { file_->finish(); }

void TourVideo::render(Renderer& renderer, const Trace& frames, const std::function<void(long)>& on_frame) {
  if (frames.empty()) throw std::invalid_argument(options_.path + ": no frames to render");
  for (const TimedCamera& frame : frames) {
    add_frame(renderer, frame);
    if (on_frame) on_frame(frames_);
  }
  finish();
}

}  // namespace catgs::server
