// Pose prediction (issue 91): a frame is rendered for where the visitor will be when it is shown,
// not where the pose was sent from. A frame is on the visitor's screen one pose-to-shown delay
// after its pose left the client (the link both ways, the server's pipeline, the decode): the
// client measures that delay and sends it on its next Pose (Pose.shown_latency_ms). The frame's
// pose moves that far ahead along the client's motion (render_core/speculation/motion_predictor.h,
// the speculation's own predictor: constant acceleration and rotation rate fitted to the recent
// poses on the client's clock), and the Frame says which pose it shows (Frame.shown_pose), so the
// page re-projects from it. The clients report pose to decoded (load_session.cpp, catgs_viewer.js);
// a decoded frame then waits for the display's next refresh, half a refresh interval on average,
// which the lead adds where the reported delay is short (kRefreshWaitFullMs .. kRefreshWaitNoneMs;
// on longer round trips more lead lost picture: docs/history/shown_picture.md, "The display's
// refresh in the lead"). What is gained and lost, measured by the shown-picture measure
// (catgs-shown): RESULTS.md "What the visitor's screen shows".
#pragma once

#include "proto/message_validation.h"
#include "speculation/motion_predictor.h"

namespace catgs::server {

class PosePrediction {
 public:
  // The lead never passes this, ms: past a few hundred ms an extrapolated pose wanders from any
  // path (a turn, a stop), and the page re-projects the frame to the true pose anyway.
  static constexpr double kMaxLeadMs = 200.0;
  // Each reported delay moves the lead this share of the way (an exponential mean: one late frame
  // does not throw the next frames ahead).
  static constexpr double kLeadGain = 0.2;
  // Poses further apart than this, ms, are no motion to follow: a page moves its camera in jumps
  // (a hotspot, setPose) or has stopped. Such a pose, and one equal to the pose before it, is
  // drawn as sent.
  static constexpr double kMaxGapMs = 100.0;
  // The display rate assumed where a Pose states none (Pose.display_hz: headsets send theirs).
  static constexpr double kDefaultDisplayHz = 60.0;
  // The half refresh is added whole while the reported delay is at most kRefreshWaitFullMs, not at
  // all from kRefreshWaitNoneMs, and in proportion between (no jump in the lead as a delay drifts).
  // The bounds sit between the delays it was measured at (loopback's, where it gained, and the
  // 40 and 80 ms round trips', where it lost; the history page above); between them it was not.
  static constexpr double kRefreshWaitFullMs = 16.0;
  static constexpr double kRefreshWaitNoneMs = 40.0;

  // A Pose arrived: its camera and client time, ms; `shown_latency_ms` > 0 is the client's
  // pose-to-decoded delay of an earlier frame (0: none reported since its last Pose);
  // `display_hz` the client's display rate (0: kDefaultDisplayHz).
  void on_pose(const CameraPose& pose, double client_time_ms, double shown_latency_ms, double display_hz = 0);
  // The pose to render for the newest pose: moved ahead by lead_ms(); the newest pose itself
  // before any delay is reported (or with a lead under 1 ms), and where it does not continue a
  // motion (kMaxGapMs).
  CameraPose predicted() const;
  // The lead, ms: the smoothed reported delay, plus the share of half a display refresh above, at
  // most kMaxLeadMs; 0 before any report.
  double lead_ms() const;

 private:
  MotionPredictor predictor_;
  CameraPose latest_;
  double latest_ms_ = 0;
  bool moving_ = false;         // the newest pose continues a motion: within kMaxGapMs of one it differs from
  double lead_ms_ = 0;          // the smoothed reported delay
  double refresh_wait_ms_ = 0;  // half the display's refresh interval
};

}  // namespace catgs::server
