// The first view of a scene and the frame the viewer navigates in (Welcome.initial_pose,
// orbit_centre, up, scene_scale): from the scene's training cameras when they are known, else
// from the scene's dense content.
//
// Frames and units: world = the scene file's frame and units. Cameras use OpenCV axes (x right,
// y down, z forward); a pose's orientation is camera-to-world. An INRIA cameras.json's rotation
// has these axes as its columns (see render_core/camera/trace.h).
#pragma once

#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

#include "camera/camera.h"
#include "scene/gaussian_model.h"
#include "proto/message_validation.h"

namespace catgs::server {

// Where a viewer starts and what it navigates around. Built once at start-up.
struct SceneFrame {
  glm::vec3 orbit_centre{0.0f};     // world; the point orbiting turns around
  glm::vec3 up{0.0f, -1.0f, 0.0f};  // world, unit; orbit and fly keep it vertical
  float scene_scale = 1.0f;         // world units: a typical viewing distance (> 0)
  // Set when the first view is a training camera; otherwise the first view frames a sphere of
  // `content_radius` around orbit_centre (first_view_pose).
  std::optional<CameraPose> training_view;
  float content_radius = 1.0f;  // world units
  // The dense content's means (world; at most kMaxFramedPoints, evenly picked) that the first
  // view frames (frame_from_content); empty: it frames the sphere of content_radius.
  std::vector<glm::vec3> content_points;
  // What the first view keeps in the picture: this share of content_points (the rest: the ragged
  // edge of a scene's content), with `margin` of the picture's width and height free on each side.
  double framed_share = 1.0;
  double margin = 0.0;
  std::string source;  // for the start-up log: "cameras FILE, camera K" or "content ..."
};

// The point nearest, in the least-squares sense, to the lines {origins[i] + s * directions[i]}:
// the p minimising sum_i |(I - d_i d_i^T)(p - o_i)|^2, i.e. the solution of
// [sum_i (I - d_i d_i^T)] p = sum_i (I - d_i d_i^T) o_i (the normal equations of that sum; d_i
// normalised here). nullopt when fewer than 2 lines are given, the sizes differ, a direction is
// zero, or the system is near singular (all lines nearly parallel: the smallest eigenvalue of
// the 3x3 matrix, relative to its mean eigenvalue, under 1e-3), where no meeting point exists.
std::optional<glm::vec3> nearest_point_to_lines(const std::vector<glm::vec3>& origins,
                                                const std::vector<glm::vec3>& directions);

// The frame from training cameras (at least one):
//   up           normalised mean of the cameras' up vectors (-y axis: y is down); -y world when
//                they cancel out.
//   orbit_centre where the optical axes meet (nearest_point_to_lines); when that fails or the
//                point lies behind most cameras (diverging or parallel axes), the cameras' mean
//                position moved along their mean viewing direction by their median distance
//                from that mean position, or 1 when they all stand at one point (a guess at what
//                a forward-facing capture looks at).
//   scene_scale  median distance from the cameras to orbit_centre.
//   first view   the camera whose optical axis points most directly at orbit_centre (the
//                smallest angle; the first such in file order): the most central training view,
//                so the first drag turns the scene about what is on screen. Its vertical field of
//                view is the camera's own (2 atan(height / (2 fy))), clamped to [20, 100] degrees.
// `file` names the cameras in `source`. Throws std::invalid_argument for no cameras.
SceneFrame frame_from_cameras(const std::vector<Camera>& cameras, const std::string& file);

// The dense part of a scene, which a first view should frame instead of the bounds of all
// Gaussians (floaters and sky or background Gaussians of unbounded captures inflate those).
struct DenseContent {
  glm::vec3 mode{0.0f};             // world: where the Gaussians are densest
  float radius = 1.0f;              // world units: the content is the ball of radius around mode
  glm::vec3 centre{0.0f};           // world: the mean of the content's means
  glm::vec3 up{0.0f, -1.0f, 0.0f};  // world, unit
  bool up_from_content = false;     // false: the -y convention (estimate ambiguous)
  double share = 0.0;               // fraction of the Gaussians in the content
};

// Estimates the dense content from the Gaussians' means (opacity-weighted where said):
//   mode    a density mode: mean shift with a flat kernel whose radius holds the nearest quarter
//           of the Gaussians (the "core"), started at the per-axis median, the kernel's points
//           weighted by opacity (nearly transparent Gaussians say little about where the
//           surfaces are). Unbounded captures put their many background Gaussians in a large
//           volume; the photographed subject is where Gaussians are densest.
//   radius  the ball around the mode grown, by percentiles of the distances from it (from
//           the 25th, in steps of 1%, up to the 98th), until the next 5% of the Gaussians would
//           need a ball 1.5 times as large (a sparse shell: the subject ends, the background
//           starts) or the density inside falls below 1/100 of the core's (a background that
//           thins out without a gap). Measured on the real scenes: flowers stops at a third of
//           its Gaussians, 2.4 units, inside the 3.9 units at which its training cameras stand;
//           biker, guitar and tumblewood (objects) keep 98%.
//   centre  the mean of the means in the ball: the middle of the content, which orbiting turns
//           about (the mode can sit to one side: a guitar's body, below its neck).
//   up      the smallest principal axis of the means in a ball 1.5 times as large (the content
//           and the ground around it: the plants of a flower bed make its own ball less flat
//           than the lawn it stands in; on flowers the axis is 8.3 degrees from the training
//           cameras' mean up with 1x, 1.9 with 1.5x, 5.4 with 2x), when those means form a
//           layer (smallest eigenvalue at most half the middle one: ground is wider than the
//           things on it are tall) and the axis is within 45 degrees of the y axis; signed
//           towards -y. Otherwise -y. 3DGS captures are reconstructed in COLMAP frames that
//           are close to y-down when the photographer held the camera upright; the principal
//           axis corrects their tilt (flowers: 18 degrees) but is not trusted to pick another
//           axis (the thinnest axis of an upright object such as biker is horizontal).
// Throws std::logic_error on an empty model.
DenseContent dense_content(const GaussianModel& model);

inline constexpr std::size_t kMaxFramedPoints = 20000;
// An object capture: the dense content holds at least this share of the Gaussians (nothing
// around it; biker, guitar and tumblewood keep 98%, the flower bed of flowers a third).
inline constexpr double kObjectShare = 0.9;
// An object's content box: per axis, the [kBoxTail, 1 - kBoxTail] quantiles of its means. It
// leaves out stray Gaussians (which would push the camera back), not a side of the object: the
// ball's 95th percentile of distances, framed before, cut off the top of a tall object (the
// biker's head, the guitar's headstock).
inline constexpr double kBoxTail = 0.002;
// An object's first view leaves this share of the picture's width and height free on each side.
inline constexpr double kFramedMargin = 0.08;
// The share of a scene's content points its first view keeps in the picture.
inline constexpr double kFramedShare = 0.95;

// The frame from the dense content:
//   up      dense_content's up; content_radius dense_content's radius;
//   object  (share >= kObjectShare) orbit_centre is the centre of the content box: per axis of
//           the first view's level frame (its right, up, and the horizontal direction between
//           them) the middle of the [kBoxTail, 1 - kBoxTail] quantiles of the means in
//           dense_content's ball; content_points are the means inside that box, all framed
//           (framed_share 1) with margin kFramedMargin. A box, not the ball: a tall object's
//           ball is much wider than the object, and its centre need not be the ball's.
//   scene   orbit_centre is dense_content's centre; content_points are the means in the ball,
//           kFramedShare of them framed, no margin (the content is part of a larger world).
//   content_points: at most kMaxFramedPoints, evenly picked;
//   scene_scale: the distance of the first view of a 16:9 viewport.
// A model of more than kJudgedGaussians content Gaussians is judged by every k-th of them
// (k = ceil(content / kJudgedGaussians)): the estimates are percentiles, a mean and a covariance,
// which an even sample of a million Gaussians gives to well within the framing's own slack, and
// the whole-scene passes over every Gaussian were most of a large city's load (issue 46;
// docs/history/level_of_detail.md "Level of detail in the server").
// (`judged`: that limit; tests pass a larger one to judge by every Gaussian.)
inline constexpr std::size_t kJudgedGaussians = std::size_t{1} << 20;
SceneFrame frame_from_content(const GaussianModel& model, std::size_t judged = kJudgedGaussians);

// The first view for a viewport of width x height: the training view when there is one (its
// own field of view), else a camera with vertical field of view `fov_deg` looking at
// orbit_centre from the side the scene's first camera usually stands on (-z, made perpendicular
// to up) raised 17 degrees towards up, its x axis horizontal (perpendicular to up), at the
// nearest distance from which framed_share of content_points project into the picture less
// `margin` on each side (or the content sphere fits the narrower field of view when there are
// no content points).
CameraPose first_view_pose(const SceneFrame& frame, int width, int height, float fov_deg = 60.0f);

// A cameras.json that belongs to `scene_path`, or "" when none exists: "<scene without
// extension>.cameras.json" or "cameras.json" in the scene's folder, else the INRIA model layout's
// MODEL/cameras.json for a scene at MODEL/point_cloud/iteration_N/point_cloud.ply.
std::string find_cameras_file(const std::string& scene_path);

// The scene's frame as the server starts: the cameras in `cameras_flag` when it is not empty
// (errors propagate: std::runtime_error naming the file and what is wrong), else a discovered
// cameras file (find_cameras_file; a bad one is reported on `log` as a warning and the content is
// used), else the content. Writes one line on `log` saying where the first view came from.
SceneFrame choose_scene_frame(const GaussianModel& model, const std::string& scene_path,
                              const std::string& cameras_flag, std::ostream& log);

}  // namespace catgs::server
