// Hotspots, measurements and walk-mode maths (issue 38). Pure (no DOM), so node unit-tests it.
//
// Annotations are the JSON of server/session/annotations.h: { version: 1, metres_per_unit?,
// hotspots: [{ id, title, text, position: [x, y, z], view?: { position, orientation, fov } }],
// tour?: [id, ...] }. The server sends its file in Annotations after Welcome; a viewer's own
// hotspots, measurement and scale travel in the share link (?notes=, base64url of the same JSON
// plus `measure: [[x, y, z], [x, y, z]]`).
//
// Screen coordinates are CSS pixels of the canvas box; the camera is the page's (OpenCV axes,
// camera-to-world quaternion [w, x, y, z]) with the intrinsics the server renders with
// (camera.js intrinsicsFor: square pixels, principal point at the centre).

import { cameraForward, intrinsicsFor, qnorm, qrotate, vadd, vdot, vlen, vscale, vsub } from './camera.js';

export const LIMITS = { hotspots: 200, id: 64, title: 120, text: 2000, bytes: 32 * 1024 };

// Where world point `p` shows on a width x height view of `pose` ({position, orientation,
// fovDeg}): {x, y, depth} in pixels of that view (x right, y down; depth along the camera's z),
// or null when it is behind the camera (depth <= 1e-6).
export function projectPoint(pose, p, width, height) {
  const conj = [pose.orientation[0], -pose.orientation[1], -pose.orientation[2], -pose.orientation[3]];
  const c = qrotate(qnorm(conj), vsub(p, pose.position)); // world -> camera
  if (!(c[2] > 1e-6)) return null;
  const k = intrinsicsFor(pose.fovDeg, width, height);
  return { x: k.fx * (c[0] / c[2]) + k.cx, y: k.fy * (c[1] / c[2]) + k.cy, depth: c[2] };
}

// The world direction (unit) of the ray through pixel (x, y) of a width x height view of `pose`.
export function pixelRay(pose, x, y, width, height) {
  const k = intrinsicsFor(pose.fovDeg, width, height);
  const d = qrotate(qnorm(pose.orientation), [(x - k.cx) / k.fx, (y - k.cy) / k.fy, 1]);
  return vscale(d, 1 / vlen(d));
}

// Distance between two world points, in scene units and, with a scale (metres per unit, > 0),
// in metres: { units, metres (or null), text }.
export function measure(a, b, metresPerUnit) {
  const units = vlen(vsub(a, b));
  const metres = metresPerUnit > 0 ? units * metresPerUnit : null;
  const text = metres !== null ? formatMetres(metres) : `${units.toPrecision(4)} units`;
  return { units, metres, text };
}

export function formatMetres(m) {
  if (m < 0.01) return `${(m * 1000).toFixed(1)} mm`;
  if (m < 1) return `${(m * 100).toFixed(1)} cm`;
  if (m < 1000) return `${m.toFixed(m < 10 ? 3 : 2)} m`;
  return `${(m / 1000).toFixed(3)} km`;
}

// The scale an author sets from one known distance: `knownMetres` is what the measured
// `units` are in reality. Throws for a non-positive or non-finite value.
export function scaleFrom(units, knownMetres) {
  if (!(units > 0) || !Number.isFinite(units)) throw new Error('measure a distance first');
  if (!(knownMetres > 0) || !Number.isFinite(knownMetres)) throw new Error('the known distance must be a positive number of metres');
  return knownMetres / units;
}

// A view (a pose) looking at `point` from `distance` away, from the side the camera `from` is on,
// with `up` kept vertical: where clicking a hotspot without a view of its own flies to.
export function viewOf(point, from, up, distance, lookAt) {
  let dir = vsub(from.position, point);
  if (!(vlen(dir) > 1e-9)) dir = vscale(cameraForward(from.orientation), -1);
  const eye = vadd(point, vscale(dir, distance / vlen(dir)));
  return { position: eye, orientation: lookAt(eye, point, up), fovDeg: from.fovDeg };
}

// ---- the annotations document ----

const finiteN = (v, n) => Array.isArray(v) && v.length === n && v.every((x) => typeof x === 'number' && Number.isFinite(x));

// Checks a document as the server does (annotations.h) and returns a clean copy; throws an Error
// naming the bad value. Used for ?notes= links and before a save, so the page says what is wrong.
export function normaliseAnnotations(doc) {
  if (!doc || typeof doc !== 'object' || Array.isArray(doc)) throw new Error('expected an object');
  if (doc.version !== 1) throw new Error('version: expected 1');
  const out = { version: 1, hotspots: [] };
  if (doc.metres_per_unit !== undefined && doc.metres_per_unit !== null) {
    if (!(doc.metres_per_unit > 0) || !Number.isFinite(doc.metres_per_unit)) throw new Error('metres_per_unit: expected a positive number');
    out.metres_per_unit = doc.metres_per_unit;
  }
  if (!Array.isArray(doc.hotspots)) throw new Error('hotspots: expected an array');
  if (doc.hotspots.length > LIMITS.hotspots) throw new Error(`hotspots: at most ${LIMITS.hotspots}`);
  const ids = new Set();
  doc.hotspots.forEach((h, i) => {
    const where = `hotspots[${i}]`;
    if (!h || typeof h !== 'object') throw new Error(`${where}: expected an object`);
    const str = (v, key, min, max) => {
      if (typeof v !== 'string' || v.length < min || new TextEncoder().encode(v).length > max) {
        throw new Error(`${where}.${key}: expected ${min}..${max} bytes of text`);
      }
      return v;
    };
    const hs = {
      id: str(h.id, 'id', 1, LIMITS.id),
      title: str(h.title, 'title', 1, LIMITS.title),
      text: h.text === undefined ? '' : str(h.text, 'text', 0, LIMITS.text),
      position: h.position,
    };
    if (!finiteN(h.position, 3)) throw new Error(`${where}.position: expected 3 numbers`);
    if (ids.has(hs.id)) throw new Error(`${where}.id: a second hotspot with this id`);
    ids.add(hs.id);
    if (h.view) {
      const v = h.view;
      if (!finiteN(v.position, 3) || !finiteN(v.orientation, 4) || !(Math.hypot(...v.orientation) > 1e-6) ||
          !(v.fov > 1 && v.fov < 170)) {
        throw new Error(`${where}.view: expected position (3 numbers), orientation (a non-zero w,x,y,z) and fov in (1, 170)`);
      }
      hs.view = { position: v.position.slice(), orientation: v.orientation.slice(), fov: v.fov };
    }
    out.hotspots.push(hs);
  });
  if (Array.isArray(doc.tour)) {
    out.tour = doc.tour.filter((id) => ids.has(id));
  }
  return out;
}

// A fresh id not in `taken` (a Set), from the title: "seat", "seat-2", ...
export function hotspotId(title, taken) {
  const base = (String(title).toLowerCase().replace(/[^a-z0-9]+/g, '-').replace(/^-|-$/g, '') || 'hotspot').slice(0, 48);
  let id = base;
  for (let k = 2; taken.has(id); k++) id = `${base}-${k}`;
  return id;
}

// The hotspots a tour steps through: the document's `tour` order when it has one, else every
// hotspot; those without a view are seen from `viewFor(h)`. Each waypoint carries its hotspot id.
export function hotspotTour(doc, viewFor) {
  const byId = new Map(doc.hotspots.map((h) => [h.id, h]));
  const order = doc.tour && doc.tour.length ? doc.tour.map((id) => byId.get(id)).filter(Boolean) : doc.hotspots;
  return order.map((h) => {
    const v = h.view ? { position: h.view.position, orientation: qnorm(h.view.orientation), fovDeg: h.view.fov } : viewFor(h);
    return { ...v, hotspot: h.id };
  });
}

// ---- the share link's ?notes= ----

function toBase64Url(text) {
  const bytes = new TextEncoder().encode(text);
  let s = '';
  for (const b of bytes) s += String.fromCharCode(b);
  return btoa(s).replace(/\+/g, '-').replace(/\//g, '_').replace(/=+$/, '');
}

function fromBase64Url(b64) {
  const s = atob(b64.replace(/-/g, '+').replace(/_/g, '/'));
  return new TextDecoder().decode(Uint8Array.from(s, (c) => c.charCodeAt(0)));
}

// The viewer's own notes as the ?notes= value: '' when there is nothing to carry.
export function encodeNotes({ hotspots = [], measure: m = null, metresPerUnit = null }) {
  if (!hotspots.length && !m && !metresPerUnit) return '';
  const doc = { version: 1, hotspots };
  if (metresPerUnit) doc.metres_per_unit = metresPerUnit;
  if (m) doc.measure = m;
  return toBase64Url(JSON.stringify(doc));
}

// ?notes= back into { hotspots, measure, metresPerUnit }; throws an Error saying what is wrong.
export function decodeNotes(value) {
  let doc;
  try {
    doc = JSON.parse(fromBase64Url(value));
  } catch {
    throw new Error('notes: not base64url JSON');
  }
  const clean = normaliseAnnotations(doc);
  let m = null;
  if (doc.measure !== undefined) {
    if (!Array.isArray(doc.measure) || doc.measure.length !== 2 || !doc.measure.every((p) => finiteN(p, 3))) {
      throw new Error('notes: measure must be two points of 3 numbers');
    }
    m = doc.measure.map((p) => p.slice());
  }
  return { hotspots: clean.hotspots, measure: m, metresPerUnit: clean.metres_per_unit ?? null };
}

// ---- walk mode ----

// One walk step: the camera moves `move` (world units, along the ground) unless a wall is
// nearer than `radius` ahead (`wallDistance`: the depth probe's distance along the move's
// direction, Infinity for none), and its height above the ground under it (`groundDistance`
// straight down along -up, Infinity for none) is eased towards `eyeHeight` (`ease` in 0..1 of the
// difference a step). Returns the new position. Gravity: with no ground, the height stays.
export function walkStep(position, move, up, { wallDistance = Infinity, groundDistance = Infinity, eyeHeight, radius, ease = 0.5 }) {
  const len = vlen(move);
  let p = position;
  if (len > 0 && !(wallDistance < len + radius)) p = vadd(p, move);
  if (Number.isFinite(groundDistance)) {
    const dh = eyeHeight - groundDistance; // > 0: too low, rise
    p = vadd(p, vscale(up, dh * ease));
  }
  return p;
}

// The part of `v` along the ground (perpendicular to `up`).
export const alongGround = (v, up) => vsub(v, vscale(up, vdot(v, up)));
