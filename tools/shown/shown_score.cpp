#include "shown/shown_score.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/image_io.h"
#include "loadgen/load_session.h"
#include "loadgen/stream_client.h"
#include "shown/page_reprojection.h"

namespace catgs::shown {

namespace {

// The camera a Pose of `c` makes on the server (and in the page): position, orientation and
// vertical field of view, principal point at the centre.
Camera as_sent(const Camera& c) {
  return loadgen::camera_from_pose(loadgen::pose_from_camera(c, 0, 0), c.width, c.height);
}

}  // namespace

RecordingPlayer::RecordingPlayer(loadgen::SessionRecording recording)
    : recording_(std::move(recording)),
      visible_(loadgen::visible_ms(recording_)),
      decoder_(std::make_unique<loadgen::VideoDecoder>("h264")) {}

Camera RecordingPlayer::display_pose(double t_ms) const {
  return as_sent(loadgen::camera_at(recording_.trace, t_ms / 1000.0 + recording_.offset_s));
}

const Image* RecordingPlayer::shown_frame(double t_ms, Camera& pose) {
  const auto& frames = recording_.frames;
  while (next_ < frames.size() && visible_[next_] <= t_ms) {
    const loadgen::RecordedFrame& f = frames[next_];
    const std::string unit = recording_.stream.substr(f.offset, f.bytes);
    int w = 0, h = 0;
    if (decoder_->decode(unit, picture_.rgba8, w, h)) {
      if (w != f.width || h != f.height)
        throw std::runtime_error("frame " + std::to_string(f.sequence) + " decoded to " + std::to_string(w) + "x" +
                                 std::to_string(h) + ", its Frame says " + std::to_string(f.width) + "x" +
                                 std::to_string(f.height));
      picture_.width = w;
      picture_.height = h;
      shown_ = static_cast<std::int64_t>(next_);
    }
    ++next_;
  }
  if (shown_ < 0) return nullptr;
  const loadgen::RecordedFrame& f = frames[static_cast<std::size_t>(shown_)];
  if (f.shown_pose) {  // the server's prediction (Frame.shown_pose): the pose the page re-projects from
    const auto& v = *f.shown_pose;
    loadgen::pb::Pose p;
    p.mutable_position()->set_x(v[0]);
    p.mutable_position()->set_y(v[1]);
    p.mutable_position()->set_z(v[2]);
    p.mutable_orientation()->set_w(v[3]);
    p.mutable_orientation()->set_x(v[4]);
    p.mutable_orientation()->set_y(v[5]);
    p.mutable_orientation()->set_z(v[6]);
    p.set_vertical_fov_deg(v[7]);
    pose = loadgen::camera_from_pose(p, f.width, f.height);
  } else {
    const double trace_s = recording_.poses[f.pose_sequence].trace_s;
    pose = as_sent(loadgen::camera_at(recording_.trace, trace_s)).rescaled(f.width, f.height);
  }
  return &picture_;
}

double RecordingPlayer::shown_age_ms(double t_ms) const {
  const loadgen::RecordedFrame& f = recording_.frames[static_cast<std::size_t>(std::max<std::int64_t>(shown_, 0))];
  return t_ms + 1000.0 * (recording_.offset_s - recording_.poses[f.pose_sequence].trace_s);
}

double page_plane_depth(const Camera& frame_pose, const Camera& display, const loadgen::SessionRecording& recording,
                        double plane_depth) {
  if (plane_depth > 0) return plane_depth;
  const PagePose from = page_pose_of(frame_pose), to = page_pose_of(display);
  const glm::dvec3 forward = to.orientation * glm::dvec3(0, 0, 1);
  const glm::dvec3 target = to.position + forward * recording.plane_distance;
  return plane_depth_for(from, target, recording.scene_scale);
}

Image page_shows(const Image& frame, const Camera& frame_pose, const Camera& display,
                 const loadgen::SessionRecording& recording, double plane_depth) {
  return shown_picture(frame, page_pose_of(frame_pose), page_pose_of(display),
                       page_plane_depth(frame_pose, display, recording, plane_depth));
}

Summary summarize(std::vector<double> v) {
  Summary s;
  s.count = v.size();
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  double sum = 0;
  for (double x : v) sum += x;
  s.mean = sum / static_cast<double>(v.size());
  s.p5 = v[static_cast<std::size_t>(0.05 * static_cast<double>(v.size() - 1) + 0.5)];
  s.min = v.front();
  return s;
}

void Row::add(const Image& picture, const Image& ideal) {
  const double p = psnr_rgba8(picture, ideal);
  psnr.push_back(std::isfinite(p) ? p : 99.0);
  ssim.push_back(ssim_luma_rgba8(picture, ideal));
}

}  // namespace catgs::shown
