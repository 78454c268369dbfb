#include "encode/mp4_file.h"

#include <cstring>
#include <stdexcept>

extern "C" {
#include <libavformat/avformat.h>
#include <libavutil/dict.h>
#include <libavutil/mem.h>
}

#include "encode/libav_encoder.h"

namespace catgs::server {

Mp4File::Mp4File(const std::string& path, int width, int height, int fps, const std::vector<std::uint8_t>& extradata)
    : path_(path), fps_(fps) {
  if (extradata.empty())
    throw std::invalid_argument(path + ": an MP4 needs the encoder's global header (EncoderConfig::global_header)");
  if (fps <= 0) throw std::invalid_argument(path + ": fps must be positive");
  auto fail = [&](const std::string& what, int err) {
    close();
    throw std::runtime_error(path + ": " + what + (err < 0 ? ": " + av_error_text(err) : std::string()));
  };
  int err = avformat_alloc_output_context2(&format_, nullptr, "mp4", path.c_str());
  if (err < 0 || !format_) fail("cannot make an MP4 muxer", err);
  stream_ = avformat_new_stream(format_, nullptr);
  packet_ = av_packet_alloc();
  if (!stream_ || !packet_) fail("out of memory", 0);
  AVCodecParameters* par = stream_->codecpar;
  par->codec_type = AVMEDIA_TYPE_VIDEO;
  par->codec_id = AV_CODEC_ID_H264;
  par->width = width;
  par->height = height;
  par->format = AV_PIX_FMT_YUV420P;
  par->color_range = AVCOL_RANGE_MPEG;  // as the encoders signal (libav_encoder.cpp)
  par->color_space = AVCOL_SPC_BT709;
  par->color_primaries = AVCOL_PRI_BT709;
  par->color_trc = AVCOL_TRC_BT709;
  par->extradata = static_cast<std::uint8_t*>(av_mallocz(extradata.size() + AV_INPUT_BUFFER_PADDING_SIZE));
  if (!par->extradata) fail("out of memory", 0);
  std::memcpy(par->extradata, extradata.data(), extradata.size());
  par->extradata_size = static_cast<int>(extradata.size());
  stream_->time_base = AVRational{1, fps};
  stream_->avg_frame_rate = AVRational{fps, 1};
  err = avio_open(&format_->pb, path.c_str(), AVIO_FLAG_WRITE);
  if (err < 0) fail("cannot open for writing", err);
  AVDictionary* options = nullptr;
  av_dict_set(&options, "movflags", "+faststart", 0);
  err = avformat_write_header(format_, &options);
  av_dict_free(&options);
  if (err < 0) fail("cannot write the MP4 header", err);
}

Mp4File::~Mp4File() { close(); }

void Mp4File::close() {
  av_packet_free(&packet_);
  if (format_) {
    if (format_->pb) avio_closep(&format_->pb);
    avformat_free_context(format_);
    format_ = nullptr;
  }
}

void Mp4File::write(const EncodedFrame& frame) {
  if (finished_ || !format_) throw std::logic_error(path_ + ": write after finish()");
  av_packet_unref(packet_);
  int err = av_new_packet(packet_, static_cast<int>(frame.data.size()));
  if (err < 0) throw std::runtime_error(path_ + ": " + av_error_text(err));
  std::memcpy(packet_->data, frame.data.data(), frame.data.size());
  packet_->stream_index = stream_->index;
  // In frames (1/fps), then in the stream's time base, which the muxer may have changed.
  packet_->pts = packet_->dts = frames_;
  packet_->duration = 1;
  av_packet_rescale_ts(packet_, AVRational{1, fps_}, stream_->time_base);
  if (frame.key_frame) packet_->flags |= AV_PKT_FLAG_KEY;
  err = av_write_frame(format_, packet_);  // in order already: one stream, no B-frames
  if (err < 0)
    throw std::runtime_error(path_ + ": cannot write frame " + std::to_string(frames_) + ": " + av_error_text(err));
  ++frames_;
}

void Mp4File::finish() {
  if (finished_ || !format_) return;
  finished_ = true;
  const int err = av_write_trailer(format_);
  const int io_err = format_->pb ? format_->pb->error : 0;
  close();
  if (err < 0 || io_err < 0)
    throw std::runtime_error(path_ + ": cannot finish the MP4 file: " + av_error_text(err < 0 ? err : io_err));
}

}  // namespace catgs::server
