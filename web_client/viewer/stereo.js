// A headset's eyes in the scene (issue 94): WebXR's views (XRView: a rigid transform in the XR
// reference space and a GL projection matrix) as the protocol's EyeViews (world position, OpenCV
// camera-to-world orientation, XrFovf-style angles), the world-from-XR mapping that anchors the
// headset to the page's camera, the intrinsics of an eye's image, and the stream's size in VR.
// Pure (no DOM), so node unit-tests it; xr.js runs the session.
//
// Axes: WebXR's camera looks along its -z with y up and x right; the protocol's (OpenCV, camera.js)
// along +z with y down. The same camera is the XR orientation followed by a half turn about x:
// R_cv = R_xr diag(1, -1, -1), i.e. q_cv = q_xr * (0, 1, 0, 0).
//
// The anchor (xrAnchor): at entering VR, the headset's pose maps onto the page's camera: its
// position to the camera's, XR up (+y) to the scene's up (Welcome.up), and the head's forward,
// level (projected on the XR floor plane), to the camera's forward projected on the scene's
// horizontal plane; so the first picture in the headset is the page's view, levelled. A metre in
// the headset is `unitsPerMetre` world units: 1 / the scene's metres per unit where the page
// knows a scale (Notes' "Set scale", walk.js's), else 1 (a scene file's unit taken as a metre).

import { cameraForward, qmul, qnorm, qrotate, quatFromAxes, vadd, vcross, vdot, vlen, vnorm, vscale, vsub } from './camera.js';

// The protocol's limits on an eye's frustum edge (proto/message_validation.h kMaxEyeAngle).
export const MAX_EYE_ANGLE = 1.5;
// The server's default largest viewport (catgs-server --max-viewport 3840x2160): a VR stream must
// fit it by pixel count and by its longer side (message_validation.h ViewportLimit). The page
// cannot read a server's own limit; a server run with a smaller one refuses the Resize.
export const SERVER_MAX_VIEWPORT = { width: 3840, height: 2160 };

const XR_TO_OPENCV = [0, 1, 0, 0]; // a half turn about x

// A GL projection matrix (column-major, 16 numbers: XRView.projectionMatrix) -> the angles of its
// frustum's edges from the forward axis, radians, as XrFovf: { left, right, up, down } with left <
// right and down < up (left and down negative for a frustum around the forward axis). From P[0] =
// 2n / (r - l), P[8] = (r + l) / (r - l) (and P[5], P[9] for y): tan(right) = r / n = (1 + P[8]) / P[0].
export function fovFromProjection(P) {
  return {
    left: Math.atan((P[8] - 1) / P[0]),
    right: Math.atan((1 + P[8]) / P[0]),
    up: Math.atan((1 + P[9]) / P[5]),
    down: Math.atan((P[9] - 1) / P[5]),
  };
}

// The vertical field of view of an eye's angles, degrees (the head pose's vertical_fov_deg: the
// level of detail's and the logs'; a server without stereo renders the head with it).
export function verticalFovDeg(angles) {
  return Math.min(Math.max(((angles.up - angles.down) * 180) / Math.PI, 1.01), 169.9);
}

// The pinhole intrinsics of a width x height image of an eye with frustum `angles` (as
// render_core/camera/camera.h Camera::from_frustum): fx = W / (tan r - tan l), cx = -tan(l) fx;
// with image y down, fy = H / (tan u - tan d), cy = tan(u) fy. Pixel coordinates are continuous:
// pixel (i, j) covers [i, i + 1) x [j, j + 1).
export function eyeIntrinsics(angles, width, height) {
  const tl = Math.tan(angles.left);
  const tr = Math.tan(angles.right);
  const tu = Math.tan(angles.up);
  const td = Math.tan(angles.down);
  const fx = width / (tr - tl);
  const fy = height / (tu - td);
  return { fx, fy, cx: -tl * fx, cy: tu * fy };
}

// An XR orientation ([w, x, y, z], camera-to-reference, XR axes) as the same camera's
// orientation in OpenCV axes.
export function openCvFromXr(q) {
  return qnorm(qmul(q, XR_TO_OPENCV));
}

// `v` projected on the plane normal to unit `up`, normalised; null when `v` is (nearly) along up.
function level(v, up) {
  const h = vsub(v, vscale(up, vdot(v, up)));
  return vlen(h) > 1e-6 ? vnorm(h) : null;
}

// A camera's forward, level: its forward projected on the horizontal plane; looking straight up or
// down, the image's top edge direction (where the view leans) instead.
function levelForward(forward, imageUp, up) {
  return level(forward, up) || level(imageUp, up) || level([1, 0, 0], up) || level([0, 0, 1], up);
}

// A rotation that takes right, up, forward (a right-handed frame with right = forward x up) to the
// x, -y, z of quatFromAxes's columns: quatFromAxes wants a rotation, so up enters as its negation.
const frameOf = (forward, up) => quatFromAxes(vcross(forward, up), vscale(up, -1), forward);

// The world-from-XR mapping at entering VR: the head's pose `head` ({ position [x, y, z] metres,
// orientation [w, x, y, z] }, XR axes, in the reference space) onto the page's camera `camera`
// ({ position, orientation }, OpenCV, world), with the scene's `up` (unit). Returns { rotation
// (world-from-XR quaternion), translation, scale (world units per metre) }: world = translation +
// scale * rotation(p).
export function xrAnchor(camera, up, head, unitsPerMetre = 1) {
  const U = vnorm(up);
  const Y = [0, 1, 0];
  const camForward = cameraForward(camera.orientation);
  const camImageUp = qrotate(camera.orientation, [0, -1, 0]);
  const worldFrame = frameOf(levelForward(camForward, camImageUp, U), U);
  const headForward = qrotate(head.orientation, [0, 0, -1]);
  const headImageUp = qrotate(head.orientation, [0, 1, 0]);
  const xrFrame = frameOf(levelForward(headForward, headImageUp, Y), Y);
  const rotation = qnorm(qmul(worldFrame, conj(xrFrame)));
  const scale = unitsPerMetre > 0 && Number.isFinite(unitsPerMetre) ? unitsPerMetre : 1;
  const translation = vsub(camera.position, vscale(qrotate(rotation, head.position), scale));
  return { rotation, translation, scale };
}

const conj = (q) => [q[0], -q[1], -q[2], -q[3]];

// A pose in the XR reference space ({ position (metres), orientation [w, x, y, z], XR axes }) as
// a camera in the world: { position, orientation (OpenCV, camera-to-world) }.
export function worldPose(anchor, xrPose) {
  return {
    position: vadd(anchor.translation, vscale(qrotate(anchor.rotation, xrPose.position), anchor.scale)),
    orientation: openCvFromXr(qmul(anchor.rotation, xrPose.orientation)),
  };
}

// A world direction (unit or not) as the XR reference space's.
export function xrDirection(anchor, worldVector) {
  return qrotate(conj(anchor.rotation), worldVector);
}

// An XRRigidTransform's position and orientation (DOMPointReadOnly's x, y, z, w) as arrays.
export function xrPoseOf(transform) {
  const p = transform.position;
  const o = transform.orientation;
  return { position: [p.x, p.y, p.z], orientation: [o.w, o.x, o.y, o.z] };
}

// One XRView (`view`: { transform, projectionMatrix }) as an EyeView in the world: { position,
// orientation, angles }, what protocol.js encodePose takes as leftEye / rightEye.
export function eyeViewOf(anchor, view) {
  const a = fovFromProjection(view.projectionMatrix);
  const clamp = (v) => Math.min(Math.max(v, -MAX_EYE_ANGLE + 1e-6), MAX_EYE_ANGLE - 1e-6);
  return { ...worldPose(anchor, xrPoseOf(view.transform)), angles: { left: clamp(a.left), right: clamp(a.right), up: clamp(a.up), down: clamp(a.down) } };
}

// The anchor moved by `delta` (world units): the visitor walks (a thumbstick) while the headset
// stays where it is in the room.
export function moveAnchor(anchor, delta) {
  return { ...anchor, translation: vadd(anchor.translation, delta) };
}

// The stream's size in VR: the eyes side by side (`eyes` 2; 1 for a headset that shows one view),
// each `eyeWidth` x `eyeHeight` display pixels (XRWebGLLayer.getViewport of a view) times `scale`
// (the viewer's render scale), scaled down together until the whole fits `limit` by pixel count
// and longer side (SERVER_MAX_VIEWPORT; each side at most 4096, the protocol's), an eye's width
// even (4:2:0 chroma pairs columns, and the server splits the width into two even halves).
// -> { eyeWidth, width: eyes * eyeWidth, height }.
export function vrStreamSize(eyeWidth, eyeHeight, scale = 1, eyes = 2, limit = SERVER_MAX_VIEWPORT) {
  let w = Math.max(eyeWidth * scale, 8);
  let h = Math.max(eyeHeight * scale, 16);
  const long = Math.max(limit.width, limit.height);
  const k = Math.min(1, Math.sqrt((limit.width * limit.height) / (eyes * w * h)), long / Math.max(eyes * w, h), 4096 / (eyes * w), 4096 / h);
  w *= k;
  h *= k;
  const even = (v, lo) => Math.max(lo, Math.floor((v + 1e-6) / 2) * 2);
  const eye = even(w, 16 / eyes);
  return { eyeWidth: eye, width: eyes * eye, height: even(h, 16) };
}
