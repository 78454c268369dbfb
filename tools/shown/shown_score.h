// The shown-picture measure (issue 91): what a visitor's screen shows at each display refresh,
// scored against the ideal picture of where the visitor is then.
//
// At refresh time t (ms on a recording's clock) the visitor is at the trace's pose of time
// t / 1000 + offset_s (loadgen/recording.h). The screen shows the newest frame visible by then
// (recording.h visible_ms: arrival, the link's rate, half the round trip), re-projected by the
// page from the pose it answers to that display pose (page_reprojection.h, the twin of the page's
// reproject.js and display.js). The ideal is full detail at the display pose, rendered `aa` times
// larger in each direction and box-filtered down (common/image_io.h box_downsample), as
// catgs-bench's yardstick.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "loadgen/recording.h"
#include "loadgen/video_decoder.h"
#include "renderer/renderer.h"

namespace catgs::shown {

// One session's recording played back refresh by refresh: the frames are decoded in order as
// the refresh time passes them (an H.264 stream decodes only in order).
class RecordingPlayer {
 public:
  explicit RecordingPlayer(loadgen::SessionRecording recording);
  const loadgen::SessionRecording& recording() const { return recording_; }
  // The visitor's pose at refresh time t_ms (camera_at of the trace at t_ms / 1000 + offset_s).
  Camera display_pose(double t_ms) const;
  // Advances to refresh time t_ms (never backwards) and returns the newest frame visible by then,
  // with the camera it was rendered for in `pose`; null while none is. Throws std::runtime_error
  // when a frame does not decode or decodes to another size than its Frame said.
  const Image* shown_frame(double t_ms, Camera& pose);
  // How old the shown frame's Pose is at refresh time t_ms: the display pose's trace time less
  // that of the Pose it answers, ms (after shown_frame(t_ms) returned a frame; a predicted frame
  // shows a pose ahead of its Pose, so its picture is younger than this).
  double shown_age_ms(double t_ms) const;
  // The shown frame's index in the recording (-1: none yet).
  std::int64_t shown_index() const { return shown_; }
  // When the first frame is visible, ms (+inf for a recording without frames).
  double first_visible_ms() const { return visible_.empty() ? 1e300 : visible_.front(); }

 private:
  loadgen::SessionRecording recording_;
  std::vector<double> visible_;                     // visible_ms(recording_)
  std::unique_ptr<loadgen::VideoDecoder> decoder_;  // held so a player moves
  std::size_t next_ = 0;                            // the next frame to decode
  std::int64_t shown_ = -1;                         // the frame in `picture_`
  Image picture_;
};

// The page's plane depth for showing a frame of `frame_pose` at `display` (below), or
// `plane_depth` where it is > 0.
double page_plane_depth(const Camera& frame_pose, const Camera& display, const loadgen::SessionRecording& recording,
                        double plane_depth);

// What the page shows at `display` of `frame` (rendered for `frame_pose`): the page's
// re-projection with its plane (the orbit target held recording.plane_distance ahead of the
// display pose, its depth along the frame's forward axis: catgs_viewer.js _updateReprojection).
// `plane_depth` > 0 replaces the page's plane by one at that depth along the frame's forward axis
// (what another plane would show; not the page).
Image page_shows(const Image& frame, const Camera& frame_pose, const Camera& display,
                 const loadgen::SessionRecording& recording, double plane_depth = 0);

// Mean and the worst 5% (the 5th percentile) of a row's per-refresh scores.
struct Summary {
  std::size_t count = 0;
  double mean = 0, p5 = 0, min = 0;
};
Summary summarize(std::vector<double> values);

// One row of the table: a picture's PSNR (dB, over 8-bit RGB; an identical picture counts as
// 99 dB) and SSIM (luma) at each refresh against the ideal.
struct Row {
  std::string name;
  std::vector<double> psnr, ssim;
  std::vector<double> detail;  // per refresh: the LOD bound drawn (px) or the shown frame's age (ms)
  void add(const Image& picture, const Image& ideal);
};

}  // namespace catgs::shown
