// A C++ twin of the web page's latency hiding: the last decoded frame re-projected to the
// visitor's current pose exactly as the page shows it, so an offline scorer can compute "what the
// visitor's screen shows" between a pose leaving and its frame arriving.
//
// The page's code, which each function here follows formula for formula and operation for
// operation in double precision (JS numbers are IEEE doubles, so the results agree to the last bit
// or two; tests/unit/page_reprojection_test.cpp checks them against the page's own module under
// node):
//   web_client/viewer/reproject.js  reprojection, applyHomography, planeDepthFor, invert3,
//                                   cssTransform, edgeFill
//   web_client/viewer/display.js    ViewDisplay.reproject, _fillBackdrop, _shrinkFrame, samePose
//   web_client/viewer/camera.js     intrinsicsFor, qrotate, cameraForward
// The one thing not in the page's code is the browser: how it samples a canvas shown through a
// CSS transform and how drawImage shrinks a canvas. shown_picture() models both as a browser does
// on a desktop GPU (bilinear, clamp to edge; an area average), which is close, not byte-exact.
//
// Conventions as camera.js and render_core/camera/camera.h: OpenCV camera axes (x right, y down,
// z forward); a pose's orientation is the camera-to-world unit quaternion; pixel (i, j) covers
// [i, i + 1) x [j, j + 1), so the image centre is (width / 2, height / 2); matrices are rows.
#pragma once

#include <array>
#include <optional>

#include <glm/gtc/quaternion.hpp>
#include <glm/vec3.hpp>

#include "camera/camera.h"
#include "renderer/renderer.h"

namespace catgs::shown {

// A pose as the page holds it (camera.js OrbitCamera.pose(): { position, orientation, fovDeg }).
struct PagePose {
  glm::dvec3 position{0.0};                    // camera centre, world units
  glm::dquat orientation{1.0, 0.0, 0.0, 0.0};  // camera-to-world, (w, x, y, z); unit length
  double fov_deg = 60.0;                       // full vertical field of view, degrees
};

// A 3x3 matrix as rows (reproject.js's [[a, b, c], [d, e, f], [g, h, i]]).
using Mat3 = std::array<std::array<double, 3>, 3>;

// Pinhole intrinsics in pixels (camera.js intrinsicsFor's { fx, fy, cx, cy }).
struct Intrinsics {
  double fx = 1.0, fy = 1.0, cx = 0.0, cy = 0.0;
};

// The pose of a render-core camera (Camera::position, orientation, vertical_fov_deg), widened to
// double. The server builds its Camera from the page's Pose in float (Camera::from_pose), so this
// is the page's pose to float precision (about 1e-7 relative), not bit for bit.
PagePose page_pose_of(const Camera& c);

// display.js samePose: the same fov, position and orientation components, compared exactly (==;
// q and -q are different poses here, as on the page).
bool same_pose(const PagePose& a, const PagePose& b);

// camera.js intrinsicsFor (the render core's Camera::from_pose, in double): square pixels,
// principal point at the image centre, fy = height / (2 tan(vfov / 2)).
Intrinsics intrinsics_for(double fov_deg, int width, int height);

// camera.js qrotate: v rotated by unit quaternion q (q v q*), expanded as the page expands it
// (v + 2 w (u x v) + u x (2 u x v)) so the rounding is the page's.
glm::dvec3 qrotate(const glm::dquat& q, const glm::dvec3& v);

// reproject.js reprojection: the homography (rows) that the plane facing `from` at `plane_depth`
// (world units along from's forward axis, > 0; not checked, as on the page: 0 gives inf/NaN)
// induces between a width x height image rendered at `from` and one at `to` (Hartley & Zisserman,
// "Multiple View Geometry", 2nd ed., sec. 13.1): H = K2 (R + t n^T / d) K1^-1 with n = (0, 0, 1),
// R = W2 W1^T, t = W2 (p1 - p2), W the world-to-camera rotations. Maps from's pixels (continuous
// coordinates) to to's; exact at every depth for a pure turn, at the plane's depth otherwise.
Mat3 plane_reprojection(const PagePose& from, const PagePose& to, double plane_depth, int width, int height);

// reproject.js applyHomography: H applied to pixel (x, y); nullopt when the point is behind the
// new camera or at its horizon (the homogeneous w not > 1e-9; NaN counts as behind).
std::optional<std::array<double, 2>> apply_homography(const Mat3& H, double x, double y);

// reproject.js planeDepthFor: the distance of `target` (world, e.g. the orbit target) along the
// pose's forward axis, or `fallback` when that is not > 1e-6 (target behind or at the camera).
double plane_depth_for(const PagePose& pose, const glm::dvec3& target, double fallback);

// reproject.js invert3: the inverse by cofactors; nullopt when |det| is not > 1e-300 (singular or
// NaN).
std::optional<Mat3> invert3(const Mat3& m);

// The homography the browser applies for reproject.js cssTransform(H, w, h, w, h) (a CSS box the
// size of the canvas, so no stretch): H / H[2][2], each element rounded to 9 significant digits as
// the page writes it into matrix3d() (Number(x.toPrecision(9))). Rounding here is printf's %.9g,
// which differs from toPrecision only on exact decimal ties (toPrecision rounds them away from 0).
Mat3 css_homography(const Mat3& H);

// reproject.js edgeFill, byte for byte: fills `out` (RGBA8, out.width x out.height, a view of a
// width x height canvas at a smaller size) with the frame `src` (RGBA8, src.width x src.height,
// the width x height frame shrunk) re-projected by H (a width x height frame's homography): each
// out pixel inside the outline of the moved frame (the quad H maps its corners to) takes the frame
// pixel it came from (nearest, no filtering), each outside takes the colour at the outline's
// nearest point, so an uncovered edge continues the frame's edge instead of being black. Colour
// from src's R, G, B; alpha 255. Only out.rgba8 is written (resized to out.width * out.height * 4
// if needed). Returns false, out untouched, when H is singular or a corner of the frame maps
// behind the new camera (the page shows no transform then). Throws std::invalid_argument when
// width, height, out's or src's size is < 1 or src.rgba8 does not hold src.width * src.height * 4
// bytes.
bool edge_fill(const Mat3& H, int width, int height, const Image& src, Image& out);

// display.js _fillBackdrop's backdrop size for a width x height canvas: at most 256 pixels across,
// k = min(1, 256 / max(w, h)), each side max(1, Math.round(side * k)).
struct Size {
  int width = 0, height = 0;
};
Size backdrop_size(int width, int height);

// display.js _shrinkFrame (drawImage(canvas, 0, 0, bw, bh)) modelled as the area average a
// browser's downscale approximates: each target pixel the mean of the source area it covers
// (fractional pixels weighted by their covered part), rounded half up; alpha 255. The same size
// returns a copy of the RGBA8 bytes. Throws std::invalid_argument for sizes < 1 or a frame whose
// rgba8 does not hold width * height * 4 bytes. Only rgba8 is filled.
Image shrink_area_average(const Image& frame, int target_width, int target_height);

// Bilinear sample of an RGBA8 image at continuous pixel coordinates (x, y), texel centres at
// +0.5, clamp to edge (how a browser samples a scaled or transformed canvas without
// image-rendering: pixelated). Returns R, G, B as unrounded values in [0, 255].
std::array<double, 3> sample_bilinear(const Image& img, double x, double y);

// What display.js shows when the canvas holding `frame` (RGBA8, rendered at `from`; its CSS box
// frame.width x frame.height, device pixel ratio 1) is shown at pose `to` (ViewDisplay.reproject
// with depthOf() = plane_depth): the plain frame (a copy of its rgba8) when the poses are the same
// (same_pose) or a corner maps behind the new camera. Otherwise each output pixel centre
// (i + 0.5, j + 0.5) maps through the inverse of the CSS matrix (css_homography) into the canvas:
// inside [0, w] x [0, h] the frame sampled bilinearly; outside the backdrop behind the canvas:
// the frame shrunk to backdrop_size (shrink_area_average), edge_fill'ed by the unrounded H into an
// image of the same size, stretched by CSS to the box (sampled bilinearly at the pixel centre
// scaled to the backdrop). The canvas's anti-aliased outline (a browser blends the edge pixels
// the outline cuts) is a hard in/out test here. Returns RGBA8 (rgb left empty), alpha 255.
// Throws std::invalid_argument for an empty frame or one whose rgba8 size does not match.
Image shown_picture(const Image& frame, const PagePose& from, const PagePose& to, double plane_depth);

}  // namespace catgs::shown
