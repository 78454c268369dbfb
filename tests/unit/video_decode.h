// What FFmpeg reads back from an MP4 file (libavformat's demuxer and libavcodec's H.264 decoder:
// not our reader or our stream decoder), and catgs-render run as a tool: the video tests'
// independent checks (tour_video_test.cpp, video_export_test.cpp).
#pragma once

#include <string>
#include <vector>

extern "C" {
#include <libavutil/rational.h>
}

#include "camera/trace.h"
#include "renderer/renderer.h"

namespace catgs::test {

struct DecodedVideo {
  std::string codec;
  int width = 0, height = 0;
  AVRational frame_rate{0, 1};
  int level = 0;                // level_idc in the avcC
  double duration_s = 0;        // the stream's duration, as its header says
  std::vector<double> times_s;  // each decoded frame's presentation time
  std::vector<bool> key;        // each decoded frame is a key frame
  std::vector<Image> frames;    // RGB, BT.709 limited range expanded to full range
};

// Demuxes `path` with libavformat's MP4 demuxer and decodes every frame with libavcodec's H.264
// decoder, opened from the file's own codec parameters (its avcC), converting to RGB with
// swscale's BT.709 limited-range coefficients.
DecodedVideo decode_file(const std::string& path);

struct ToolRun {
  int status = -1;
  std::string output;  // stdout and stderr
};

// Runs catgs-render (CATGS_RENDER_BIN) with `arguments`, its output into the file `log`.
ToolRun catgs_render(const std::string& arguments, const std::string& log);

// A short orbit around the bundled biker: `frames` cameras at `rate` a second, 40 degrees of arc,
// width x height, a vertical field of view of 50 degrees.
Trace biker_orbit(int frames, double rate, int width, int height);

}  // namespace catgs::test
