// A frame's encoder settings in one call (frame_encoding.h).
#include "encode/frame_encoding.h"

#include <algorithm>

namespace catgs::server {

int rate_cap_kbps(int client_kbps, int link_kbps) {
  return link_kbps > 0 && client_kbps > 0 ? std::min(client_kbps, link_kbps) : std::max(client_kbps, link_kbps);
}

FrameEncoding frame_encoding(const EncoderPolicy& policy, const FrameEncodeInputs& in) {
  FrameEncoding e;
  e.policy = policy;
  if (policy.content_rate && in.probed_bits_per_pixel > 0) e.policy.bits_per_pixel = in.probed_bits_per_pixel;
  const int live = std::max(1, in.live_sessions);
  // The link: its cap against the policy's rate at this size, both in bits a second on the wire.
  // The VBV's rate is per frame at the stream's frame rate (kStreamFps unless the client says), so a stream at fewer frames a second
  // sends that share of it; at least 10 frames a second's share: frames written slowly because
  // the link is jammed must not each get a larger share of the cap (a frame of half a second on
  // the wire at 2 frames/s makes the jam worse).
  const int fps = std::max(1, in.fps);
  const double fps_share = std::clamp(in.link.frame_rate / fps, 10.0 / fps, 1.0);
  // The config under the client's cap alone: the frame's own where the link does not limit.
  e.config = encoder_config(e.policy, in.width, in.height, fps, live, in.client_max_kbps);
  const int ceiling = e.config.bitrate_kbps;
  e.link_ceiling_kbps = ceiling > 0 ? std::max(1, static_cast<int>(ceiling * fps_share)) : 0;
  if (in.link.limiting) {
    const double on_wire = e.link_ceiling_kbps > 0
                               ? std::min(in.link.cap_kbps, static_cast<double>(e.link_ceiling_kbps))
                               : in.link.cap_kbps;
    e.link_kbps = std::max(1, static_cast<int>(on_wire * in.link.encoder_gain / fps_share));
  }
  // Where the link limits, the config under its cap too: its rate, preset and threads are the frame's.
  if (e.link_kbps > 0)
    e.config = encoder_config(e.policy, in.width, in.height, fps, live, rate_cap_kbps(in.client_max_kbps, e.link_kbps));
  e.rate_kbps = e.config.bitrate_kbps;
  e.preset = e.config.x264_preset;
  e.threads = e.config.threads;
  // While the link limits, the VBV holds two frames' share of the cap: a frame may then take at
  // most two frame intervals on the link, where the policy's buffer would let one take six, a
  // latency spike of half a second on a slow link.
  e.vbv_ms = e.link_kbps > 0 ? kLinkVbvMs : e.policy.vbv_buffer_ms;
  if (e.rate_kbps > 0) e.config.vbv_buffer_ms = e.vbv_ms;
  // AV1 cannot follow the link's rate without a key frame: a limiting link keeps H.264.
  e.av1 = use_av1(e.policy, in.width, in.height, fps, live, in.av1_ok, true, e.link_kbps > 0);
  e.step = e.av1 ? kPresetSteps
                 : (e.policy.x264_preset == "auto" ? preset_step(e.policy, in.width, in.height, fps, live) : 0);
  e.lift_cap = in.refine && e.rate_kbps > 0;
  return e;
}

}  // namespace catgs::server
