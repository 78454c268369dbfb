// An H.264 video file: the access units of an Encoder opened with global_header, muxed into MP4
// by libavformat (ISO BMFF; its avcC box made from the encoder's extradata, the Annex B access
// units rewritten with length prefixes by the muxer; "faststart": the index before the media, so
// the file plays while it downloads).
//
// Timing: frame k is presented at k / fps seconds and lasts 1 / fps (no B-frames: decode order is
// presentation order). Used by one thread.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "encode/encoder.h"

struct AVFormatContext;
struct AVStream;
struct AVPacket;

namespace catgs::server {

class Mp4File {
 public:
  // Creates (or truncates) `path` for a width x height stream at `fps` frames a second with the
  // encoder's global header `extradata` (Encoder::extradata(), not empty). Throws
  // std::invalid_argument for empty extradata or fps <= 0, std::runtime_error naming the path
  // when it cannot be written (a missing folder, no permission) or the header cannot be made.
  Mp4File(const std::string& path, int width, int height, int fps, const std::vector<std::uint8_t>& extradata);
  ~Mp4File();  // without finish(): the file is closed, unplayable (no index)
  Mp4File(const Mp4File&) = delete;
  Mp4File& operator=(const Mp4File&) = delete;

  // Appends the next frame's access unit. Throws std::runtime_error naming the path on a write
  // error (a full disk), std::logic_error after finish().
  void write(const EncodedFrame& frame);
  // Writes the index (moved to the front: faststart) and closes the file. Throws
  // std::runtime_error naming the path on a write error.
  void finish();

  std::int64_t frames() const { return frames_; }

 private:
  void close();  // frees every libav object (safe on partially built files)

  std::string path_;
  AVFormatContext* format_ = nullptr;
  AVStream* stream_ = nullptr;
  AVPacket* packet_ = nullptr;
  int fps_ = 0;
  std::int64_t frames_ = 0;
  bool finished_ = false;
};

}  // namespace catgs::server
