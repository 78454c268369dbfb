// Encoders: a picture converted with the reference BT.709 conversion and encoded from its I420
// planes decodes back to the source, the conversion hits the standard's code values, IDR on
// demand, and NVENC's failure path (no NVENC on this machine, or on H100/H200) with `auto`
// falling back to x264 and saying why. AV1 (libaom realtime): its temporal units follow the AV1
// spec's low-overhead format (section 5, read here by hand) and decode with libavcodec's AV1
// decoder (libdav1d: another project's decoder) to the source.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/image_io.h"
#include "camera/camera.h"
#include "cpu/cpu_renderer.h"
#include "encode/av1_encoder.h"
#include "encode/encoder.h"
#include "loadgen/video_decoder.h"
#include "process/first_view.h"
#include "test_data.h"
#include "colour/yuv420.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/log.h>
}

namespace {

// x264 prints a banner and statistics per encoder otherwise.
const int kQuietLibav = (av_log_set_level(AV_LOG_ERROR), 0);

using namespace catgs;
using namespace catgs::server;

// The bundled biker seen from the server's first view.
Image biker_picture(int w, int h) {
  auto model = test::cached_scene(test::bundled_scene());
  const CameraPose p = first_view_pose(frame_from_content(*model), w, h);
  Image img;
  cpu::CpuRenderer(model, RenderOptions{})
      .render(Camera::from_pose(p.position, p.orientation, p.vertical_fov_deg, w, h), img);
  return img;
}

Image decode(const EncodedFrame& f) {
  loadgen::VideoDecoder dec;
  Image out;
  EXPECT_TRUE(dec.decode(std::string(f.data.begin(), f.data.end()), out.rgba8, out.width, out.height));
  return out;
}

EncoderConfig config(int w, int h) {
  EncoderConfig c;
  c.width = w;
  c.height = h;
  c.crf = 12;
  return c;
}

TEST(Yuv420, Bt709LimitedRangeCodeValues) {
  // 2x2 blocks of white, black, red, and a flat 50% grey, side by side.
  const std::uint8_t colours[4][3] = {{255, 255, 255}, {0, 0, 0}, {255, 0, 0}, {128, 128, 128}};
  std::vector<std::uint8_t> rgba(8 * 2 * 4);
  for (int r = 0; r < 2; ++r)
    for (int c = 0; c < 8; ++c)
      for (int k = 0; k < 3; ++k) rgba[(r * 8 + c) * 4 + k] = colours[c / 2][k];
  const Yuv420Image yuv = rgba_to_yuv420_bt709(rgba.data(), 8, 2, 8 * 4);
  // BT.709-6: white (235, 128, 128), black (16, 128, 128), red (63, 102, 240).
  const int want[4][3] = {{235, 128, 128}, {16, 128, 128}, {63, 102, 240}, {126, 128, 128}};
  for (int b = 0; b < 4; ++b) {
    SCOPED_TRACE(b);
    EXPECT_EQ(yuv.y[static_cast<std::size_t>(2 * b)], want[b][0]);
    EXPECT_EQ(yuv.y[static_cast<std::size_t>(8 + 2 * b + 1)], want[b][0]);
    EXPECT_EQ(yuv.u[static_cast<std::size_t>(b)], want[b][1]);
    EXPECT_EQ(yuv.v[static_cast<std::size_t>(b)], want[b][2]);
  }
  EXPECT_THROW(rgba_to_yuv420_bt709(rgba.data(), 7, 2, 32), std::invalid_argument);
}

// An RGBA8 picture, converted on the host, encoded from its I420 planes.
EncodedFrame encode_rgba(Encoder& encoder, const Image& picture, bool force_idr) {
  const Yuv420Image yuv = rgba_to_yuv420_bt709(picture.rgba8.data(), picture.width, picture.height, picture.width * 4);
  return encoder.encode_yuv420(yuv.planes(), force_idr);
}

TEST(Encoder, Yuv420PathDecodesToTheSource) {
  const int W = 192, H = 128;
  const Image src = biker_picture(W, H);
  auto enc = make_encoder("x264", config(W, H));
  const EncodedFrame f = encode_rgba(*enc, src, false);
  EXPECT_TRUE(f.key_frame) << "the first frame is an IDR";
  const Image decoded = decode(f);
  ASSERT_EQ(decoded.width, W);
  ASSERT_EQ(decoded.height, H);
  const double vs_source = psnr_rgba8(decoded, src);
  std::cout << "[ info ] I420 path vs source " << vs_source << " dB\n";
  EXPECT_GE(vs_source, 35.0);
}

TEST(Encoder, Yuv420PathHonoursStridesAndIdrOnDemand) {
  const int W = 64, H = 48;
  const Image src = biker_picture(W, H);
  const Yuv420Image yuv = rgba_to_yuv420_bt709(src.rgba8.data(), W, H, W * 4);
  // The same planes with padded rows (a pitched GPU copy).
  const int ys = W + 32, cs = W / 2 + 16;
  std::vector<std::uint8_t> y(static_cast<std::size_t>(ys * H), 0), u(static_cast<std::size_t>(cs * H / 2), 0),
      v(static_cast<std::size_t>(cs * H / 2), 0);
  for (int r = 0; r < H; ++r)
    std::copy_n(&yuv.y[static_cast<std::size_t>(r * W)], W, &y[static_cast<std::size_t>(r * ys)]);
  for (int r = 0; r < H / 2; ++r) {
    std::copy_n(&yuv.u[static_cast<std::size_t>(r * W / 2)], W / 2, &u[static_cast<std::size_t>(r * cs)]);
    std::copy_n(&yuv.v[static_cast<std::size_t>(r * W / 2)], W / 2, &v[static_cast<std::size_t>(r * cs)]);
  }
  auto tight = make_encoder("x264", config(W, H)), pitched = make_encoder("x264", config(W, H));
  const Yuv420Planes padded{y.data(), ys, u.data(), cs, v.data(), cs};
  EXPECT_EQ(tight->encode_yuv420(yuv.planes(), false).data, pitched->encode_yuv420(padded, false).data);
  EXPECT_FALSE(pitched->encode_yuv420(padded, false).key_frame);
  EXPECT_TRUE(pitched->encode_yuv420(padded, true).key_frame);
  EXPECT_THROW(pitched->encode_yuv420(Yuv420Planes{y.data(), W / 2, u.data(), cs, v.data(), cs}, false),
               std::invalid_argument);
}

TEST(Yuv420, PitchedTargetHoldsTheSameCodeValuesAsPacked) {
  const Image src = biker_picture(96, 64);
  const Yuv420Image packed = rgba_to_yuv420_bt709(src.rgba8.data(), 96, 64, 96 * 4);
  const int ys = 96 + 32, cs = 48 + 16;
  std::vector<std::uint8_t> y(ys * 64, 7), u(cs * 32, 7), v(cs * 32, 7);
  rgba_to_yuv420_bt709(src.rgba8.data(), 96, 64, 96 * 4,
                       Yuv420Target{96, 64, MemoryKind::host, y.data(), ys, u.data(), cs, v.data(), cs});
  for (int r = 0; r < 64; ++r) {
    ASSERT_TRUE(std::equal(packed.y.begin() + r * 96, packed.y.begin() + (r + 1) * 96, y.begin() + r * ys)) << r;
    EXPECT_EQ(y[r * ys + 96], 7) << "padding written at row " << r;
  }
  for (int r = 0; r < 32; ++r) {
    ASSERT_TRUE(std::equal(packed.u.begin() + r * 48, packed.u.begin() + (r + 1) * 48, u.begin() + r * cs)) << r;
    ASSERT_TRUE(std::equal(packed.v.begin() + r * 48, packed.v.begin() + (r + 1) * 48, v.begin() + r * cs)) << r;
  }
  Yuv420Image other;
  EXPECT_THROW(rgba_to_yuv420_bt709(src.rgba8.data(), 96, 64, 96 * 4, other.target(64, 64)), std::invalid_argument);
  Yuv420Target device = other.target(96, 64);
  device.memory = MemoryKind::device;
  EXPECT_THROW(rgba_to_yuv420_bt709(src.rgba8.data(), 96, 64, 96 * 4, device), std::invalid_argument);
}

// The server's path: the renderer writes the converted frame into the encoder's own planes.
TEST(Encoder, RenderIntoInputTargetEqualsRenderThenConvert) {
  auto model = test::cached_scene(test::bundled_scene());
  const CameraPose p = first_view_pose(frame_from_content(*model), 128, 96);
  const Camera cam = Camera::from_pose(p.position, p.orientation, p.vertical_fov_deg, 128, 96);
  cpu::CpuRenderer renderer(model, RenderOptions{});
  Image img;
  renderer.render(cam, img);
  const Yuv420Image ref = rgba_to_yuv420_bt709(img.rgba8.data(), 128, 96, 128 * 4);

  auto direct = make_encoder("x264", config(128, 96));
  auto copied = make_encoder("x264", config(128, 96));
  EXPECT_THROW(direct->encode_input(false), std::logic_error);
  const Yuv420Target t = direct->input_target();
  EXPECT_EQ(t.memory, MemoryKind::host);
  EXPECT_GE(renderer.render_yuv420_at(cam, 0.0, t), 0.0);
  for (int r = 0; r < 96; ++r)
    ASSERT_TRUE(std::equal(ref.y.begin() + r * 128, ref.y.begin() + (r + 1) * 128, t.y + r * t.y_stride)) << r;
  const EncodedFrame a = direct->encode_input(false);
  EXPECT_TRUE(a.key_frame);
  EXPECT_EQ(a.data, copied->encode_yuv420(ref.planes(), false).data);
  EXPECT_THROW(direct->encode_input(false), std::logic_error) << "one picture per input_target()";

  Yuv420Image wrong;
  EXPECT_THROW(renderer.render_yuv420_at(cam, 0.0, wrong.target(64, 48)), std::invalid_argument);
  Yuv420Target device = wrong.target(128, 96);
  device.memory = MemoryKind::device;
  EXPECT_THROW(renderer.render_yuv420_at(cam, 0.0, device), std::invalid_argument);
}

// The picture a decoder shows, against the encoder's input: PSNR over the three planes by sample
// count, from libavcodec's own H.264 decoder (not x264's reconstruction), one access unit at a
// time. Returns the PSNR of each access unit, in order.
std::vector<double> decoded_psnr_db(const std::vector<EncodedFrame>& stream, const std::vector<Yuv420Image>& inputs) {
  const AVCodec* codec = avcodec_find_decoder(AV_CODEC_ID_H264);
  AVCodecContext* ctx = avcodec_alloc_context3(codec);
  EXPECT_EQ(avcodec_open2(ctx, codec, nullptr), 0);
  AVPacket* packet = av_packet_alloc();
  AVFrame* frame = av_frame_alloc();
  std::vector<double> out;
  for (std::size_t i = 0; i < stream.size(); ++i) {
    std::vector<std::uint8_t> bytes = stream[i].data;
    bytes.resize(bytes.size() + AV_INPUT_BUFFER_PADDING_SIZE, 0);
    packet->data = bytes.data();
    packet->size = static_cast<int>(stream[i].data.size());
    EXPECT_EQ(avcodec_send_packet(ctx, packet), 0);
    EXPECT_EQ(avcodec_receive_frame(ctx, frame), 0) << "access unit " << i;
    const Yuv420Image& in = inputs[i];
    double sse = 0, samples = 0;
    const auto plane = [&](const std::vector<std::uint8_t>& want, int w, int h, int p) {
      for (int r = 0; r < h; ++r)
        for (int c = 0; c < w; ++c) {
          const double d = frame->data[p][r * frame->linesize[p] + c] - want[static_cast<std::size_t>(r * w + c)];
          sse += d * d;
        }
      samples += static_cast<double>(w) * h;
    };
    plane(in.y, in.width, in.height, 0);
    plane(in.u, in.width / 2, in.height / 2, 1);
    plane(in.v, in.width / 2, in.height / 2, 2);
    out.push_back(10.0 * std::log10(255.0 * 255.0 / (sse / samples)));
  }
  av_frame_free(&frame);
  av_packet_free(&packet);
  avcodec_free_context(&ctx);
  return out;
}

// The encoder's picture that stats and /metrics give each session (EncodedFrame::psnr_db) is
// what a decoder shows: the walk past the biker, encoded as the server does (capped CRF, sliced
// threads), at a loose and a tight rate cap.
TEST(Encoder, X264ReportsThePictureADecoderShows) {
  const int W = 192, H = 128;
  auto model = test::cached_scene(test::bundled_scene());
  const CameraPose p = first_view_pose(frame_from_content(*model), W, H);
  cpu::CpuRenderer renderer(model, RenderOptions{});
  std::vector<Yuv420Image> pictures;
  for (int i = 0; i < 8; ++i) {
    Image img;
    const glm::vec3 step = p.orientation * glm::vec3(0.02f * static_cast<float>(i), 0.0f, 0.0f);
    renderer.render(Camera::from_pose(p.position + step, p.orientation, p.vertical_fov_deg, W, H), img);
    pictures.push_back(rgba_to_yuv420_bt709(img.rgba8.data(), W, H, W * 4));
  }
  for (const int kbps : {4000, 150}) {
    SCOPED_TRACE(kbps);
    EncoderConfig c = config(W, H);
    c.crf = 23;
    c.bitrate_kbps = kbps;
    c.threads = 2;
    auto enc = make_encoder("x264", c);
    std::vector<EncodedFrame> stream;
    for (std::size_t i = 0; i < pictures.size(); ++i)
      stream.push_back(enc->encode_yuv420(pictures[i].planes(), i == 4));
    const std::vector<double> decoded = decoded_psnr_db(stream, pictures);
    double mean = 0;
    for (std::size_t i = 0; i < stream.size(); ++i) {
      EXPECT_NEAR(stream[i].psnr_db, decoded[i], 0.01) << "access unit " << i;
      mean += decoded[i] / static_cast<double>(stream.size());
    }
    std::cout << "[ info ] x264 at " << kbps << " kbit/s: decoded " << mean << " dB a picture\n";
  }
}

// Whether NVENC opens here; its error text when not.
std::string nvenc_error() {
  try {
    make_encoder("nvenc", config(256, 256));
    return "";
  } catch (const std::runtime_error& e) {
    return e.what();
  }
}

TEST(Encoder, NvencFailsWithAReasonOrEncodes) {
  const std::string err = nvenc_error();
  if (err.empty()) {
    // A GPU with NVENC: the stream must decode to the picture.
    const Image src = biker_picture(256, 256);
    auto e = make_encoder("nvenc", config(256, 256));
    EXPECT_EQ(e->name(), "nvenc");
    const EncodedFrame f = encode_rgba(*e, src, false);
    EXPECT_TRUE(f.key_frame);
    EXPECT_GE(psnr_rgba8(decode(f), src), 30.0);
    return;
  }
  std::cout << "[ info ] nvenc: " << err << "\n";
  EXPECT_EQ(err.rfind("nvenc: ", 0), 0u) << err;
  EXPECT_GT(err.size(), 30u) << "the reason must say what failed: " << err;
}

// NVENC fed CUDA frames (device_input): hands out device planes where it opens, else fails with
// a reason like the host-fed one.
TEST(Encoder, NvencDeviceInputGivesDevicePlanesOrFailsWithAReason) {
  EncoderConfig c = config(256, 256);
  c.device_input = true;
  try {
    auto e = make_encoder("nvenc", c);
    const Yuv420Target t = e->input_target();
    EXPECT_EQ(t.memory, MemoryKind::device);
    EXPECT_GE(t.y_stride, 256);
    EXPECT_THROW(e->encode_yuv420(Yuv420Image{}.planes(), false), std::logic_error);
  } catch (const std::runtime_error& e) {
    const std::string err = e.what();
    std::cout << "[ info ] nvenc (device input): " << err << "\n";
    EXPECT_EQ(err.rfind("nvenc: ", 0), 0u) << err;
    EXPECT_GT(err.size(), 30u) << err;
  }
}

TEST(Encoder, AutoFallsBackToX264AndSaysWhy) {
  const std::string err = nvenc_error();
  for (int i = 0; i < 2; ++i) {  // the second call reuses the probe's verdict
    std::string why;
    bool fell_back = true;
    auto e = make_encoder("auto", config(64, 64), &why, &fell_back);
    if (err.empty()) {
      EXPECT_EQ(e->name(), "nvenc");
      EXPECT_FALSE(fell_back);
      continue;
    }
    EXPECT_EQ(e->name(), "x264");
    EXPECT_TRUE(fell_back);
    EXPECT_NE(why.find("nvenc: "), std::string::npos) << why;
    EXPECT_EQ(why.find('\n'), std::string::npos) << "one line: " << why;
    EXPECT_EQ(e->encode_yuv420(
                   rgba_to_yuv420_bt709(std::vector<std::uint8_t>(64 * 64 * 4, 90).data(), 64, 64, 256).planes(), false)
                  .key_frame,
              true);
  }
  bool fell_back = true;
  EXPECT_EQ(make_encoder("x264", config(64, 64), nullptr, &fell_back)->name(), "x264");
  EXPECT_FALSE(fell_back);
}

TEST(Encoder, RejectsUnknownKindAndBadSize) {
  EXPECT_THROW(make_encoder("vp9", config(64, 64)), std::invalid_argument);
  EXPECT_THROW(make_encoder("x264", config(63, 64)), std::invalid_argument);
  EXPECT_THROW(make_encoder("nvenc", config(8, 8)), std::invalid_argument);
}

// One OBU of a temporal unit (AV1 spec 5.3): its obu_type and payload size.
struct Obu {
  int type = 0;
  std::size_t size = 0;
};

// The OBUs of a low-overhead temporal unit (AV1 spec 5.3.1-5.3.2, leb128 sizes 4.10.5); every
// OBU must carry obu_has_size_field, as the format requires. Adds a failure and stops on
// malformed data.
std::vector<Obu> split_obus(const std::vector<std::uint8_t>& tu) {
  std::vector<Obu> out;
  std::size_t p = 0;
  while (p < tu.size()) {
    const std::uint8_t h = tu[p++];
    EXPECT_EQ(h & 0x80, 0) << "obu_forbidden_bit";
    const bool extension = (h & 0x04) != 0, has_size = (h & 0x02) != 0;
    EXPECT_TRUE(has_size) << "every OBU of the low-overhead format has a size";
    if (!has_size) return out;
    p += extension ? 1 : 0;
    std::size_t size = 0;
    for (int i = 0; i < 8 && p < tu.size(); ++i) {
      const std::uint8_t b = tu[p++];
      size |= static_cast<std::size_t>(b & 0x7f) << (7 * i);
      if (!(b & 0x80)) break;
    }
    EXPECT_LE(p + size, tu.size()) << "an OBU runs past its temporal unit";
    if (p + size > tu.size()) return out;
    out.push_back({(h >> 3) & 0x0f, size});
    p += size;
  }
  return out;
}

constexpr int kObuSequenceHeader = 1, kObuTemporalDelimiter = 2, kObuFrame = 6;

bool has_obu(const std::vector<Obu>& obus, int type) {
  return std::any_of(obus.begin(), obus.end(), [type](const Obu& o) { return o.type == type; });
}

TEST(Av1Encoder, TemporalUnitsDecodeToTheSourceWithKeyFramesOnDemand) {
  const int W = 256, H = 144;
  const Image src = biker_picture(W, H);
  auto enc = make_encoder("av1", config(W, H));
  EXPECT_EQ(enc->name(), "av1");
  EXPECT_EQ(enc->codec(), "av1");
  loadgen::VideoDecoder dec("av1");
  for (int k = 0; k < 4; ++k) {
    SCOPED_TRACE(k);
    const bool force = k == 3;
    const EncodedFrame f = encode_rgba(*enc, src, force);
    EXPECT_EQ(f.key_frame, k == 0 || force) << "a key frame first and on demand, none between";
    const std::vector<Obu> obus = split_obus(f.data);
    ASSERT_FALSE(obus.empty());
    EXPECT_EQ(obus.front().type, kObuTemporalDelimiter) << "a temporal unit starts with its delimiter";
    EXPECT_EQ(obus.front().size, 0u);
    EXPECT_EQ(has_obu(obus, kObuSequenceHeader), f.key_frame) << "the sequence header in band on key frames only";
    EXPECT_TRUE(has_obu(obus, kObuFrame) || has_obu(obus, 3)) << "a frame (or frame header) OBU";
    Image out;
    ASSERT_TRUE(dec.decode(std::string(f.data.begin(), f.data.end()), out.rgba8, out.width, out.height))
        << "one picture out per temporal unit in: no frame of delay";
    ASSERT_EQ(out.width, W);
    ASSERT_EQ(out.height, H);
    const double vs_source = psnr_rgba8(out, src);
    std::cout << "[ info ] AV1 frame " << k << " vs source " << vs_source << " dB, " << f.data.size() << " bytes\n";
    EXPECT_GE(vs_source, 35.0);
  }
  // A key frame starts a stream: a fresh decoder takes the forced one alone.
  const EncodedFrame key = encode_rgba(*enc, src, true);
  loadgen::VideoDecoder fresh("av1");
  Image out;
  EXPECT_TRUE(fresh.decode(std::string(key.data.begin(), key.data.end()), out.rgba8, out.width, out.height));
}

TEST(Av1Encoder, RateCapHoldsAndCqLevelFollowsCrf) {
  // crf 0..51 onto cq-level 0..63 by the same share of the scale.
  EXPECT_EQ(av1_cq_level(0), 0);
  EXPECT_EQ(av1_cq_level(51), 63);
  EXPECT_EQ(av1_cq_level(23), 28);  // 23 * 63 / 51 = 28.4
  EXPECT_EQ(av1_cq_level(80), 63);
  // Tile columns: log2(threads) at most, each column at least 256 pixels wide.
  EXPECT_EQ(av1_tile_columns_log2(1920, 1), 0);
  EXPECT_EQ(av1_tile_columns_log2(1920, 4), 2);
  EXPECT_EQ(av1_tile_columns_log2(1920, 16), 2);  // 1920 / 8 = 240 < 256
  EXPECT_EQ(av1_tile_columns_log2(640, 8), 1);
  EXPECT_EQ(av1_tile_columns_log2(320, 8), 0);
  // Then rows, until every thread has a tile, each at least 128 pixels tall.
  EXPECT_EQ(av1_tile_rows_log2(1080, 16, 2), 2);  // 4 x 4 tiles of 480 x 270
  EXPECT_EQ(av1_tile_rows_log2(720, 8, 2), 1);    // 4 x 2 of 320 x 360
  EXPECT_EQ(av1_tile_rows_log2(720, 4, 2), 0);    // the columns already give 4 threads a tile
  EXPECT_EQ(av1_tile_rows_log2(240, 8, 0), 0);    // 120 pixels would be too short
  // A capped stream of a moving view keeps near its cap; a tight cap costs quality.
  const int W = 320, H = 192;
  const auto model = test::cached_scene(test::bundled_scene());
  const SceneFrame scene = frame_from_content(*model);
  const CameraPose p = first_view_pose(scene, W, H);
  cpu::CpuRenderer renderer(model, RenderOptions{});
  std::vector<Image> frames(24);
  for (std::size_t k = 0; k < frames.size(); ++k) {
    // A pan of 1% of the viewing distance a frame: every frame brings new pixels.
    const glm::vec3 step(0.01f * scene.scene_scale * static_cast<float>(k), 0.0f, 0.0f);
    renderer.render(Camera::from_pose(p.position + step, p.orientation, p.vertical_fov_deg, W, H), frames[k]);
  }
  const auto stream = [&](int kbps, double& psnr) {
    EncoderConfig c = config(W, H);
    c.crf = 4;  // a floor far above what the cap allows
    c.bitrate_kbps = kbps;
    c.vbv_buffer_ms = 200;
    Av1Encoder enc(c);
    loadgen::VideoDecoder dec("av1");
    double bytes = 0;
    psnr = 0;
    for (const Image& f : frames) {
      const EncodedFrame e = encode_rgba(enc, f, false);
      bytes += static_cast<double>(e.data.size());
      Image out;
      EXPECT_TRUE(dec.decode(std::string(e.data.begin(), e.data.end()), out.rgba8, out.width, out.height));
      psnr += psnr_rgba8(out, f) / static_cast<double>(frames.size());
    }
    return bytes * 8 * c.fps / static_cast<double>(frames.size()) / 1000;  // kbit/s
  };
  double tight_psnr = 0, loose_psnr = 0;
  const double tight = stream(150, tight_psnr), loose = stream(3000, loose_psnr);
  std::cout << "[ info ] AV1 at a 150 kbit/s cap: " << tight << " kbit/s, " << tight_psnr << " dB; at 3000: " << loose
            << " kbit/s, " << loose_psnr << " dB\n";
  EXPECT_LE(tight, 150 * 1.5) << "the first key frame included";
  EXPECT_GT(loose, tight);
  EXPECT_GT(loose_psnr, tight_psnr);
  EXPECT_GT(tight_psnr, 25.0);  // still the scene
  // libaom cannot change a running encoder's rate: the session rebuilds it (a key frame).
  Av1Encoder enc(config(W, H));
  EXPECT_FALSE(enc.set_max_bitrate_kbps(500, 0));
}

TEST(Av1Encoder, RefusesBadSpeedAndSize) {
  EncoderConfig c = config(64, 64);
  c.av1_speed = 4;
  EXPECT_THROW(make_encoder("av1", c), std::invalid_argument);
  c.av1_speed = 11;
  EXPECT_THROW(make_encoder("av1", c), std::invalid_argument);
  EXPECT_THROW(make_encoder("av1", config(63, 64)), std::invalid_argument);
  EXPECT_THROW(loadgen::VideoDecoder("vp9"), std::invalid_argument);
}

}  // namespace
