// The encode side of a session's frames (stream_encoder.h): the encoder brought to each frame's
// settings (encode/frame_encoding.h) and the content-rate probe.
#include "session/stream_encoder.h"

#include <algorithm>
#include <iostream>

#include "encode/encoder_policy.h"

namespace catgs::server {

StreamEncoder::~StreamEncoder() {
  if (probe_ && content_rates_) content_rates_->release(probe_->width(), probe_->height());
}

void StreamEncoder::open(bool av1_ok, std::shared_ptr<ContentRates> content_rates, int gpu, bool device_input,
                         std::string scene_name) {
  av1_ok_ = av1_ok;
  content_rates_ = std::move(content_rates);
  gpu_ = gpu;
  device_input_ = device_input;
  scene_name_ = std::move(scene_name);
}

FrameEncodeInputs StreamEncoder::inputs(const JobShape& shape, bool refine, int live_sessions) const {
  FrameEncodeInputs in;
  in.width = shape.width;
  in.height = shape.height;
  in.client_max_kbps = shape.max_bitrate_kbps;
  in.link = shape.link;
  in.refine = refine;
  in.live_sessions = live_sessions;
  in.av1_ok = av1_ok_;
  in.fps = shape.fps;
  // The probe's table is read (a lock) only where --bits-per-pixel auto uses it.
  const bool probed = settings_.encoder_policy.content_rate && content_rates_;
  in.probed_bits_per_pixel = probed ? content_rates_->bits_per_pixel(shape.width, shape.height) : 0;
  return in;
}

int StreamEncoder::live_sessions() const {
  return static_cast<int>(std::max<std::int64_t>(1, metrics_.sessions_open.load()));
}

bool StreamEncoder::stream_is_av1(const JobShape& shape, int live_sessions) const {
  return frame_encoding(settings_.encoder_policy, inputs(shape, false, live_sessions)).av1;
}

FrameEncoding StreamEncoder::prepare(const JobShape& s, bool refine, bool& idr) {
  const FrameEncoding e = frame_encoding(settings_.encoder_policy, inputs(s, refine, live_sessions()));
  const auto now = std::chrono::steady_clock::now();
  const bool same_stream =
      encoder_ && encoder_->width() == s.width && encoder_->height() == s.height && bitrate_kbps_ == s.max_bitrate_kbps;
  // The still view's refine frame: the stream's crf with no rate cap where x264 can take a new
  // VBV rate for one frame (the next frame sets the stream's again); NVENC's and AV1's encoders
  // would be rebuilt (an IDR each way), so they keep theirs: a still frame under CBR still gets
  // the whole frame's budget for what is left to refine.
  if (e.lift_cap && same_stream && encoder_->name() == "x264" &&
      encoder_->set_max_bitrate_kbps(kRefineKbps, kRefineVbvMs)) {
    // This frame lifts the stream's cap (not an earlier refine frame's): x264 plans it against
    // the buffer's fill the capped frames left, which says nothing of the crf.
    refine_lifted_cap_ = rate_kbps_ != kRefineKbps;
    rate_kbps_ = kRefineKbps;
    vbv_ms_ = kRefineVbvMs;
    return e;
  }
  // The link's cap follows the link frame by frame, and a probed content rate takes effect when
  // its probe ends: x264 takes a new VBV rate without an IDR. (An AV1 stream cannot: it is
  // rebuilt below; a limiting link moves it to H.264, use_av1.)
  if (same_stream && (rate_kbps_ != e.rate_kbps || vbv_ms_ != e.vbv_ms) && encoder_->codec() == "h264" &&
      e.rate_kbps > 0 && encoder_->set_max_bitrate_kbps(e.rate_kbps, e.vbv_ms)) {
    rate_kbps_ = e.rate_kbps;
    vbv_ms_ = e.vbv_ms;
  }
  if (same_stream && rate_kbps_ == e.rate_kbps && vbv_ms_ == e.vbv_ms) {
    // The same stream: rebuilt only for a new share of the cores (x264's threads, preset and the
    // codec are fixed when it opens; NVENC has none to share). A link that comes to limit an AV1
    // stream lowers the step, so should_rebuild moves it to H.264 at once.
    const auto since = now - built_;
    const bool threads = should_rebuild(threads_, e.threads, since);
    const bool preset = should_rebuild(step_, e.step, since);
    if (encoder_->name() == "nvenc" || !(threads || preset)) return e;
    metrics_.encoder_rebuilds_total++;
  }
  EncoderConfig cfg = e.config;
  // One-job path: a GPU frame goes to NVENC as a CUDA frame (no host copy); x264 ignores it.
  cfg.device_input = device_input_;
  cfg.cuda_device = std::max(gpu_, 0);
  // The requested kind: "auto" reuses the process's NVENC probe and may fall back per session.
  bool fell_back = false;
  encoder_ = make_encoder(e.av1 ? "av1" : settings_.encoder, cfg, nullptr, &fell_back);
  const std::string was = label_;
  label_ = encoder_->name() == "x264" ? "x264 " + cfg.x264_preset : encoder_->name();
  if (!was.empty() && e.step < step_) {
    // The ladder stepped down (sessions joined; encoder_policy.h): the picture falls, said here,
    // in /metrics, and in each Stats (encoder, encode_psnr_db_mean), never silently.
    metrics_.encoder_steps_down_total++;
    std::cerr << "encoder: " << was << " -> " << label_ << " at " << live_sessions() << " sessions\n";
  }
  bitrate_kbps_ = s.max_bitrate_kbps;
  rate_kbps_ = cfg.bitrate_kbps;
  vbv_ms_ = e.vbv_ms;
  threads_ = cfg.threads;
  step_ = e.step;
  built_ = now;
  if (fell_back) metrics_.encoder_fallbacks_total++;
  idr = true;
  return e;
}

void StreamEncoder::probe_content_rate(const JobShape& shape, const CameraPose& pose, const FrameEncoding& settings,
                                       const Yuv420Planes& planes) {
  const EncoderPolicy& policy = settings_.encoder_policy;
  // --bitrate off or a fixed rate wins over the probe.
  if (!policy.content_rate || policy.bitrate_kbps >= 0 || !content_rates_) return;
  const int w = shape.width, h = shape.height;
  if (probe_ && (probe_->width() != w || probe_->height() != h)) {  // a new size: its own probe
    content_rates_->release(probe_->width(), probe_->height());
    probe_.reset();
  }
  if (!probe_) {
    if (!content_rates_->claim(w, h)) return;  // measured, or another session measures it
    try {
      // The stream's own x264 preset (the ladder's step now; an AV1 stream: the step below it).
      probe_ = std::make_unique<ContentRateProbe>(policy, w, h, std::max(1, threads_), settings.preset);
    } catch (const std::exception&) {
      content_rates_->release(w, h);
      return;
    }
    probe_last_pose_.reset();
  }
  // A still camera's frames say nothing about motion, and cost next to nothing: not counted.
  if (probe_last_pose_ && probe_last_pose_->position == pose.position &&
      probe_last_pose_->orientation == pose.orientation && probe_last_pose_->vertical_fov_deg == pose.vertical_fov_deg)
    return;
  probe_last_pose_ = pose;
  try {
    probe_->add(planes);
  } catch (const std::exception& e) {  // the probe's failure is not the stream's: it keeps its cap
    std::cerr << "content rate: probe at " << w << "x" << h << " failed, the policy's rate kept: " << e.what() << "\n";
    content_rates_->set(w, h, policy.bits_per_pixel);  // not tried again at this size
    probe_.reset();
    return;
  }
  if (!probe_->done()) return;
  const double crf_bpp = probe_->crf_bits_per_pixel(), bpp = content_bits_per_pixel(crf_bpp);
  content_rates_->set(w, h, bpp);
  metrics_.content_rate_probes_total++;
  std::cerr << "content rate: scene '" << scene_name_ << "' at " << w << "x" << h << ": crf " << policy.crf << " takes "
            << crf_bpp << " bits a pixel, the cap " << bpp << "\n";
  probe_.reset();
}

}  // namespace catgs::server
