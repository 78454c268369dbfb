#include "video_decode.h"

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <glm/geometric.hpp>

#include "scene/scene_bounds.h"
#include "test_data.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libswscale/swscale.h>
}

namespace catgs::test {

DecodedVideo decode_file(const std::string& path) {
  DecodedVideo v;
  AVFormatContext* fmt = nullptr;
  if (avformat_open_input(&fmt, path.c_str(), nullptr, nullptr) < 0) throw std::runtime_error("cannot open " + path);
  if (avformat_find_stream_info(fmt, nullptr) < 0) throw std::runtime_error("no stream info in " + path);
  if (fmt->nb_streams != 1) throw std::runtime_error(path + ": expected one stream");
  const AVStream* st = fmt->streams[0];
  const AVCodec* codec = avcodec_find_decoder(st->codecpar->codec_id);
  v.codec = codec ? codec->name : "?";
  v.frame_rate = st->avg_frame_rate;
  v.level = st->codecpar->level;
  v.duration_s = static_cast<double>(st->duration) * av_q2d(st->time_base);
  AVCodecContext* dec = avcodec_alloc_context3(codec);
  avcodec_parameters_to_context(dec, st->codecpar);
  dec->thread_count = 1;
  if (avcodec_open2(dec, codec, nullptr) < 0) throw std::runtime_error("cannot open the decoder");
  AVPacket* pkt = av_packet_alloc();
  AVFrame* frame = av_frame_alloc();
  SwsContext* sws = nullptr;
  auto drain = [&]() {
    while (avcodec_receive_frame(dec, frame) == 0) {
      v.width = frame->width;
      v.height = frame->height;
      sws = sws_getCachedContext(sws, frame->width, frame->height, static_cast<AVPixelFormat>(frame->format),
                                 frame->width, frame->height, AV_PIX_FMT_RGBA, SWS_BICUBIC | SWS_ACCURATE_RND, nullptr,
                                 nullptr, nullptr);
      const int* coeffs = sws_getCoefficients(SWS_CS_ITU709);
      sws_setColorspaceDetails(sws, coeffs, 0, coeffs, 1, 0, 1 << 16, 1 << 16);
      Image img;
      img.width = frame->width;
      img.height = frame->height;
      img.rgba8.resize(static_cast<std::size_t>(img.width) * img.height * 4);
      std::uint8_t* dst[1] = {img.rgba8.data()};
      const int dst_stride[1] = {4 * img.width};
      sws_scale(sws, frame->data, frame->linesize, 0, frame->height, dst, dst_stride);
      v.frames.push_back(std::move(img));
      v.times_s.push_back(static_cast<double>(frame->best_effort_timestamp) * av_q2d(st->time_base));
      v.key.push_back(frame->key_frame != 0);
    }
  };
  while (av_read_frame(fmt, pkt) >= 0) {
    avcodec_send_packet(dec, pkt);
    av_packet_unref(pkt);
    drain();
  }
  avcodec_send_packet(dec, nullptr);  // flush
  drain();
  sws_freeContext(sws);
  av_frame_free(&frame);
  av_packet_free(&pkt);
  avcodec_free_context(&dec);
  avformat_close_input(&fmt);
  return v;
}

ToolRun catgs_render(const std::string& arguments, const std::string& log) {
  const std::string cmd = std::string(CATGS_RENDER_BIN) + " " + arguments + " > " + log + " 2>&1";
  ToolRun r;
  r.status = std::system(cmd.c_str());
  std::ifstream in(log);
  std::stringstream ss;
  ss << in.rdbuf();
  r.output = ss.str();
  return r;
}

Trace biker_orbit(int frames, double rate, int width, int height) {
  const auto model = cached_scene(bundled_scene());
  const Bounds b = robust_bounds(*model, 0.02f);
  GeneratorParams p;
  p.duration_s = (frames - 1) / rate;
  p.rate_hz = rate;
  p.width = width;
  p.height = height;
  p.fov_deg = 50.0f;
  return make_orbit(b, 1.6f * glm::length(b.extent()), 0.0f, 40.0f, p);
}

}  // namespace catgs::test
