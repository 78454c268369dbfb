// A view in the page's address: ?scene=name&pos=x,y,z&rot=w,x,y,z&fov=deg (the Welcome's scene
// name, world units, camera-to-world quaternion in OpenCV axes, vertical field of view), the same
// numbers a Pose carries: a pose means something only in its scene's world. Pure (no DOM), so
// node unit-tests it.

import { qnorm } from './viewer/viewer.js';

// Parameters a shared link must not carry: the access token is the sender's, not the view's.
const PRIVATE_PARAMS = ['token'];
const VIEW_PARAMS = ['scene', 'pos', 'rot', 'fov'];

// 7 significant digits: below a float32's resolution, which is what the renderer uses.
const fmt = (v) => String(Number(v.toPrecision(7)));

// The page URL `href` with the view `pose` of scene `scene` written in (other parameters kept,
// the token dropped).
export function viewUrl(href, pose, scene = '') {
  const u = new URL(href);
  for (const k of PRIVATE_PARAMS) u.searchParams.delete(k);
  if (scene) u.searchParams.set('scene', scene);
  else u.searchParams.delete('scene');
  u.searchParams.set('pos', pose.position.map(fmt).join(','));
  u.searchParams.set('rot', qnorm(pose.orientation).map(fmt).join(','));
  u.searchParams.set('fov', fmt(pose.fovDeg));
  u.hash = '';
  return u.toString();
}

// The address without the view parameters (what "reset view" leaves in the address bar).
export function withoutView(href) {
  const u = new URL(href);
  for (const k of VIEW_PARAMS) u.searchParams.delete(k);
  return u.toString();
}

// The view in `search` (a URLSearchParams): null when the link has none, else { pose, scene }
// (scene '' when the link names none) or { error } saying which parameter is bad.
export function parseView(params) {
  if (!['pos', 'rot', 'fov'].some((k) => params.has(k))) return null;
  const nums = (k, n) => {
    const s = params.get(k);
    if (s === null) return null;
    const v = s.split(',').map((x) => (x.trim() === '' ? NaN : Number(x)));
    return v.length === n && v.every(Number.isFinite) ? v : undefined;
  };
  const position = nums('pos', 3);
  const rot = nums('rot', 4);
  const fov = nums('fov', 1);
  if (!position) return { error: 'pos must be 3 numbers x,y,z' };
  if (!rot || Math.hypot(...rot) < 1e-6) return { error: 'rot must be a non-zero quaternion w,x,y,z' };
  if (fov === undefined || (fov && !(fov[0] > 1 && fov[0] < 170))) return { error: 'fov must be degrees in (1, 170)' };
  return { pose: { position, orientation: qnorm(rot), fovDeg: fov ? fov[0] : null }, scene: params.get('scene') || '' };
}
