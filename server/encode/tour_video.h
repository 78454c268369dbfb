// A camera path rendered to an H.264 MP4 file (catgs-render --video, and the server's "Export
// video": session/video_export.h): every frame rendered at full quality (no frame is skipped or
// late: a file has no deadline), converted to BT.709 I420 by the renderer (on the GPU for the
// CUDA core), encoded by the server's x264 encoder (x264_encoder.h) with a global header, and
// muxed by libavformat (mp4_file.h).
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "camera/trace.h"
#include "encode/encoder.h"
#include "encode/mp4_file.h"
#include "renderer/renderer.h"

namespace catgs::server {

struct TourVideoOptions {
  std::string path;               // the .mp4 to write (created or truncated)
  int width = 0, height = 0;      // pixels, even; H.264 level <= 6.2 at fps (encode/h264_level.h)
  int fps = 60;                   // frames a second of the video
  int crf = 18;                   // x264's constant rate factor (quality: 0 lossless .. 51)
  std::string preset = "medium";  // x264 preset
  double keyframe_seconds = 2.0;  // an IDR picture this often, where a player can seek to
  int threads = 0;                // x264's threads (0: its own choice, every core)
};

// The video file, opened before any rendering so that a bad path or size fails at once.
class TourVideo {
 public:
  // Checks the options and opens the encoder and the file. Throws std::invalid_argument for a
  // bad size, fps or crf (saying which, and the H.264 level limit a size breaks),
  // std::runtime_error naming the path when the file cannot be written or the encoder opened.
  explicit TourVideo(const TourVideoOptions& options);

  // Renders one frame (a camera of the options' size; frame k is shown at k / fps) and appends
  // it. Throws std::invalid_argument for a camera of another size; render and encoder errors
  // propagate (the caller removes the unfinished file).
  void add_frame(Renderer& renderer, const TimedCamera& frame);
  // Writes the index and closes the file (mp4_file.h). Throws as Mp4File::finish().
  void finish();
  long frames() const { return frames_; }

  // add_frame() for each of `frames`, then finish(). `on_frame` (may be empty) hears the count
  // of frames written after each. Throws std::invalid_argument for an empty trace.
  void render(Renderer& renderer, const Trace& frames, const std::function<void(long)>& on_frame = {});

 private:
  TourVideoOptions options_;
  long keyframe_every_ = 1;
  long frames_ = 0;
  std::unique_ptr<Encoder> encoder_;
  std::unique_ptr<Mp4File> file_;
};

}  // namespace catgs::server
