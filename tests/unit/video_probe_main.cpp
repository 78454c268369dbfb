// catgs-video-probe FILE: what FFmpeg's MP4 demuxer and H.264 decoder read from FILE
// (video_decode.h), as one JSON line: {"codec", "width", "height", "frames", "fps",
// "duration_s"}. The browser test (tests/e2e/export_e2e_test.mjs) checks the page's downloaded
// export with it, as ffprobe would, without needing the ffmpeg package. Exit 1 on a file FFmpeg
// cannot read.
#include <cstdio>
#include <exception>

#include "video_decode.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: catgs-video-probe FILE.mp4\n");
    return 2;
  }
  try {
    const catgs::test::DecodedVideo v = catgs::test::decode_file(argv[1]);
    std::printf(
        "{\"codec\": \"%s\", \"width\": %d, \"height\": %d, \"frames\": %zu, \"fps\": %.6f, \"duration_s\": %.6f}\n",
        v.codec.c_str(), v.width, v.height, v.frames.size(),
        v.frame_rate.den ? static_cast<double>(v.frame_rate.num) / v.frame_rate.den : 0.0, v.duration_s);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", argv[1], e.what());
    return 1;
  }
}
