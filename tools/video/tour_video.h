// A camera path rendered to an H.264 MP4 file (catgs-render --video): every frame rendered at
// full quality (no frame is skipped or late: a file has no deadline), converted to BT.709 I420
// by the renderer (on the GPU for the CUDA core), encoded by the server's x264 encoder
// (server/encode/x264_encoder.h) with a global header, and muxed by libavformat
// (server/encode/mp4_file.h).
#pragma once

#include <cstdio>
#include <memory>
#include <string>

#include "camera/trace.h"
#include "encode/encoder.h"
#include "encode/mp4_file.h"
#include "renderer/renderer.h"

namespace catgs::tools {

struct TourVideoOptions {
  std::string path;               // the .mp4 to write (created or truncated)
  int width = 0, height = 0;      // pixels, even; H.264 level <= 6.2 at fps (encode/h264_level.h)
  int fps = 60;                   // frames a second of the video
  int crf = 18;                   // x264's constant rate factor (quality: 0 lossless .. 51)
  std::string preset = "medium";  // x264 preset
  double keyframe_seconds = 2.0;  // an IDR picture this often, where a player can seek to
};

// The video file, opened before any rendering so that a bad path or size fails at once.
class TourVideo {
 public:
  // Checks the options and opens the encoder and the file. Throws std::invalid_argument for a
  // bad size, fps or crf (saying which, and the H.264 level limit a size breaks),
  // std::runtime_error naming the path when the file cannot be written or the encoder opened.
  explicit TourVideo(const TourVideoOptions& options);

  // Renders `frames` (cameras of options' size, frame k shown at k / fps) and writes them, then
  // finishes the file. `progress` (may be null) hears of each frame. Render and encoder errors
  // propagate; the caller removes the unfinished file.
  void render(Renderer& renderer, const Trace& frames, std::FILE* progress, bool progress_tty);

 private:
  TourVideoOptions options_;
  std::unique_ptr<server::Encoder> encoder_;
  std::unique_ptr<server::Mp4File> file_;
};

}  // namespace catgs::tools
