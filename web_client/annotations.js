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

import { cameraForward, intrinsicsFor, lookAt, qnorm, qrotate, vadd, vcross, vdot, vlen, vnorm, vscale, vsub } from './viewer/viewer.js';

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

// ---- walk mode (issues 38 and 64) ----
//
// Walk mode senses the scene with the server's depth probe (DepthRequest: the median depth along
// one pixel's ray of a view the page chooses; render_core/cpu/pixel_depth.h). Two things about
// that probe decide how walk mode asks (issue 64):
//  - The forward model adds 0.3 px^2 to every Gaussian's screen covariance (a low-pass filter),
//    so the pixel of a coarse view is a cone about a pixel wide (sigma 0.55 px): the centre pixel
//    of a 5-pixel view of 30 degrees probes a cone of about 3 degrees. Sparse leaves and thin
//    stems add up to a surface in such a cone, where a fine ray (the centre of a 64-pixel view of
//    30 degrees before) slips through a gap and reads the far side, or nothing. Too coarse, and
//    every speck of dust becomes a solid blob as wide as the pixel: tumblewood_sh2's grass read
//    0.22 units higher through a 10-degree pixel than through a 3-degree one, so the views up and
//    down have 33 pixels (2.7 degrees).
//  - The Jacobian is clamped to 1.3x the view's field of view, and the projection (EWA) is a
//    linearisation at each Gaussian's centre. Looking down, a large flat Gaussian whose centre
//    lies outside a narrow view (flowers_sh3's lawn under the camera is made of discs wider than
//    the camera's height) is squashed and drops out, so the views up and down are 90 degrees.
//    Looking level, a floor's discs near the feet, projected at a grazing angle, spread over the
//    level ray within about twice their size (the synthetic room's floor read as a wall 0.25
//    ahead at knee height); a narrow view clamps them, so the level views are 30 degrees.
export const WALK_PROBE_FOV = 90; // the views up and down
export const GROUND_PROBE_PIXELS = 33; // a pixel of 2.7 degrees
export const LEVEL_PROBE_FOV = 30; // the level views
export const LEVEL_PROBE_PIXELS = 5; // a pixel of 6 degrees

// Walk mode's sizes for an eye height `eye` (world units): how far short of an obstacle the eye
// stops (`radius`; beyond the renderer's near plane, inside which a probe sees nothing), the
// highest step up or down it takes (`step`: a tenth of the eye height, 16 cm for 1.6 m), the
// height of the knee probe above the ground (`knee`, a quarter of the eye height: lower, its
// cone meets a flat floor within a stop distance or two), how far ahead a look checks the
// ground (`look`), and how near it checks when the ground ahead is missing or a step away
// (`nearLook`: the camera comes that near an edge); `nearPlane` the renderer's.
export function walkSizes(eye, nearPlane = 0.2) {
  return { eye, radius: Math.max(0.25 * eye, 1.5 * nearPlane), step: 0.1 * eye, knee: 0.25 * eye, look: eye, nearLook: 0.25 * eye, nearPlane };
}

// One look: the probes to send from the eye at `position` (`up` the world's up). Options: `dir`
// the way the camera walks (unit, along the ground; null when standing), `look` how far ahead the
// ground is checked, `ground` the ground's height (up . point) under the eye when known (else the
// eye is taken to be `sizes.eye` above it), `landing` while the height is still settling onto the
// ground (the ground under and the room above only), `roll` which of the two rolls the vertical
// views take (walkVerticalView; looks alternate). Each probe is { name, pose, size }: probe the
// centre pixel (size / 2, size / 2) of a size x size view of pose.
//   under  the ground under the eye (walkGroundProbe); landing, from a little above the eye
//          (walkLift), so that the camera, wherever it was, sees all there is under the eye it
//          is to be (tumblewood_sh2's first view is less than the near plane above the top of
//          its grass and daffodils: from there the ground read 0.2 units too low);
//   above  (landing) straight up from as far under the eye: how high the eye may rise without
//          passing through something;
//   ahead  the ground `look` ahead along dir (walkGroundProbe there, at the eye's height), or the
//          top of what stands there;
//   eye    level along dir from the eye: a wall, a trunk, leaves at head height;
//   knee   level along dir from `knee` above the ground: a plant, a bed, a trunk (what is
//          lower, but more than a step high, the ahead probe finds).
export function walkProbes(position, up, sizes, { dir = null, look = sizes.look, ground = null, landing = false, roll = 0 } = {}) {
  if (landing) {
    const lift = vscale(up, walkLift(sizes));
    return [
      { name: 'under', ...walkGroundProbe(vadd(position, lift), up, sizes, roll) },
      { name: 'above', pose: walkVerticalView(vsub(position, lift), up, up, roll), size: GROUND_PROBE_PIXELS },
    ];
  }
  const probes = [{ name: 'under', ...walkGroundProbe(position, up, sizes, roll) }];
  if (!dir) return probes;
  const h = vdot(position, up);
  const kneeHeight = (ground ?? h - sizes.eye) + sizes.knee;
  const knee = vadd(position, vscale(up, kneeHeight - h));
  const level = (p) => ({ position: p, orientation: lookAt(p, vadd(p, dir), up), fovDeg: LEVEL_PROBE_FOV });
  probes.push({ name: 'ahead', ...walkGroundProbe(vadd(position, vscale(dir, look)), up, sizes, roll) });
  probes.push({ name: 'eye', pose: level(position), size: LEVEL_PROBE_PIXELS });
  probes.push({ name: 'knee', pose: level(knee), size: LEVEL_PROBE_PIXELS });
  return probes;
}

// How far ahead a look along `dir` checks the ground, after the plan `last` (or null): an eye
// height (sizes.look); near an edge or a step the last look of the same way (within 14 degrees)
// saw, half as far as that look, down to sizes.nearLook, so that the camera comes up to it.
export function walkLookDistance(last, dir, sizes) {
  if (walkSameWay(last, dir) && (last.reason === 'edge' || last.reason === 'step')) return Math.max(sizes.nearLook, last.look / 2);
  return sizes.look;
}

// Whether a walk along unit `dir` goes the way of plan `last` (within 14 degrees): its look
// distance and the steps it remembers carry over (walkLookDistance, walkPlan's steps).
const walkSameWay = (last, dir) => Boolean(dir && last && last.dir && vdot(dir, last.dir) > 0.97);

// How far above the eye a landing look's ground probe looks down from, and under it its up probe
// looks up from: the near plane and a margin, so that what is just under or above the eye is
// seen too.
export const walkLift = (sizes) => 1.25 * sizes.nearPlane;

// The probe of the ground under an eye at `position`: straight down from the eye, a 33-pixel view
// of 90 degrees at `roll` (0 or 1, walkVerticalView). { pose, size }: the ground's height
// (up . point) is up . position - the depth it answers. (What lies within the near plane under
// the eye, it does not see: from just above the eye it would, but it would also read splats at
// the eye's height, which flowers_sh3 has where a large background splat projects from far to
// the side: seen from above, not from below.)
export function walkGroundProbe(position, up, sizes, roll = 0) {
  return { pose: walkVerticalView(position, vscale(up, -1), up, roll), size: GROUND_PROBE_PIXELS };
}

// The pose of a probe view from `p` looking along `d` (up or down) with one of two rolls fixed in
// the world, whichever way the camera walks: its image's up along the world x axis on the ground
// (y where up is near x) for `roll` 0, a quarter turn from that for 1.
export function walkVerticalView(p, d, up, roll = 0) {
  const a = Math.abs(up[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
  let along = vnorm(vsub(a, vscale(up, vdot(a, up))));
  if (roll) along = vnorm(vcross(up, along));
  return { position: p, orientation: lookAt(p, vadd(p, d), along), fovDeg: WALK_PROBE_FOV };
}

// What one look says: `answers` { under, ahead, eye, knee, above } are the DepthResults ({ hit,
// depth }) of walkProbes(origin, up, sizes, { dir, look, roll, landing, ... }) (null: not asked or
// failed), the options those of that look and `previous` the plan before (or null). Returns the
// plan the camera walks by until the next look:
//   { origin, dir, look, roll, ground0, ground1, underSeen, aheadSeen, ceiling, free, allowed,
//     reason, confirmed, pending, pendingRoll, tries }
//   ground0     the ground's height (up . point) under the origin: null when none is known;
//   ground1     the ground's height `look` ahead, when it is within a step of ground0;
//   underSeen, aheadSeen  what the down probes read there (null: no surface);
//   ceiling     (a landing look) the height of what the up probe saw above the eye, or null;
//   free        how far along dir the eye and knee probes saw nothing (Infinity: nothing);
//   allowed     how far from the origin along dir the eye may go: never past what the level
//               probes proved free (free - radius), never past `look` (the ground is known that
//               far), and 0 when the ground ahead is missing ('edge': a cliff, the end of the
//               scene's floor) or more than a step up or down ('step': a bed, a rock, a drop);
//   reason      what limits `allowed` below `look`: '', 'obstacle', 'edge', 'step', 'check';
//   confirmed   whether the height may follow ground0 ('check' while not);
//   steps       the points ({ point, reason }) where this look or an earlier one of the same way
//               saw the ground ahead missing or more than a step off (walkSteps): the camera
//               stops a near look (sizes.nearLook) short of each, whatever a longer look saw
//               beyond it.
// Looks alternate between two rolls of the vertical views (`roll` 0 and 1, walkVerticalView):
// a real surface reads the same at both, while a large splat of a coarse scene, projected from
// far to the side, can show under one roll alone (flowers_sh3). So the ground under the camera
// is known once a look at each roll saw it within a step of each other: till then 'check', the
// camera holds still (one reading through a gap never pulls it down; after four looks without
// two that agree, it takes the lower of the last two). From then on a reading within a step of
// the known ground refines it; one further off, or none, is left out (the camera holds its
// height) unless the next look, at the other roll, sees the same and it is no more than half an
// eye height off: then the camera lands again there ('check': something stands under the eye
// that the ahead probe missed between two looks, or the ground fell away). Further off it is
// left out too: the camera never sinks more than half an eye height at once, and flowers_sh3
// has a "floor" that shows under a camera only from above, 1.6 units over its lawn (a background
// splat 60 units wide, projected from far to the side), which an eye raised by floaters at the
// edge of its lawn would otherwise jump onto. Standing on nothing (no ground seen: a scene
// without a floor) the camera walks level wherever the level probes see nothing, until ground
// shows under it.
export function walkPlan(origin, up, sizes, answers, { dir = null, look = sizes.look, previous = null, roll = 0, landing = false } = {}) {
  const h = vdot(origin, up);
  const depthOf = (a) => (a && a.hit && a.depth > 0 ? a.depth : null);
  const under = depthOf(answers.under);
  const ahead = depthOf(answers.ahead);
  const underSeen = under === null ? null : h + (landing ? walkLift(sizes) : 0) - under;
  const aheadSeen = ahead === null ? null : h - ahead;
  const near = (a, b) => a !== null && b !== null && a !== undefined && b !== undefined && Math.abs(a - b) <= sizes.step;
  const expected = previous && previous.confirmed ? walkGroundAt(previous, origin, up) : null;
  let ground0 = underSeen;
  let confirmed = true;
  let pending = null;
  let tries = 0;
  if (expected !== null) {
    if (near(underSeen, expected)) {
      ground0 = underSeen;
    } else if (underSeen !== null && previous.pendingRoll !== roll && near(underSeen, previous.pending) && Math.abs(underSeen - expected) <= sizes.eye / 2) {
      confirmed = false; // both rolls saw the ground move by more than a step: land again there
      tries = 1;
    } else {
      ground0 = expected; // left out, till the other roll sees it too
      pending = underSeen;
    }
  } else if (underSeen !== null) {
    const last = previous && !previous.confirmed && previous.ground0 !== null ? previous : null;
    tries = last ? last.tries + 1 : 1;
    if (last && last.roll !== roll && near(underSeen, last.ground0)) {
      confirmed = true;
    } else if (last && tries >= 4) {
      ground0 = Math.min(underSeen, last.ground0);
    } else {
      confirmed = false;
    }
  }
  const ground1 = ground0 !== null && near(aheadSeen, ground0) ? aheadSeen : null;
  const above = depthOf(answers.above);
  const ceiling = above === null ? null : h - walkLift(sizes) + above;
  const plan = {
    origin: origin.slice(), dir: dir ? dir.slice() : null, look, roll, ground0, ground1, underSeen, aheadSeen, ceiling,
    free: Infinity, allowed: 0, reason: '', confirmed, pending, pendingRoll: pending === null ? null : roll, tries, steps: [],
  };
  if (!dir) return plan;
  for (const a of [answers.eye, answers.knee]) {
    const d = depthOf(a);
    if (d !== null) plan.free = Math.min(plan.free, d);
  }
  plan.allowed = Math.max(0, Math.min(look, plan.free - sizes.radius));
  if (plan.free - sizes.radius < look) plan.reason = 'obstacle';
  if (!confirmed) {
    plan.allowed = 0;
    plan.reason = 'check';
  } else if (ground0 !== null && ground1 === null) {
    plan.allowed = 0;
    plan.reason = aheadSeen === null ? 'edge' : 'step';
  }
  plan.steps = walkSteps(plan, previous, up, sizes);
  for (const { point, reason } of plan.steps) {
    const room = Math.max(0, vdot(vsub(point, origin), dir) - sizes.nearLook);
    if (confirmed && room < plan.allowed) {
      plan.allowed = room;
      plan.reason = reason;
    }
  }
  return plan;
}

// The steps and edges a walk remembers (walkPlan's `steps`): those of the previous plan while the
// way stays the same (within 14 degrees) that still lie ahead, within the stop distance of the
// line walked; this look's ahead point when it saw the ground missing or more than a step off; and
// none within a step of this look's ahead point when it saw the ground there (the other roll saw
// what one roll alone showed: walkPlan). Why: one look checks the ground at one point, `look`
// ahead. Stopped short of a bed shallower than a look whose sides the level probes see through
// (flowers_sh3's flower bed), a fresh look from the right spot lands beyond the bed and sees the
// lawn; without this the camera then walked over the bed at lawn eye height
// (docs/history/depth_probe.md, "Walk mode over flowers_sh3's flower bed"). At most the 16
// nearest are kept.
function walkSteps(plan, previous, up, sizes) {
  const { origin, dir } = plan;
  const ahead = vadd(origin, vscale(dir, plan.look));
  const flat = (v) => vsub(v, vscale(up, vdot(v, up)));
  const kept = (walkSameWay(previous, dir) && previous.steps ? previous.steps : []).filter(({ point }) => {
    const d = flat(vsub(point, origin));
    const along = vdot(d, dir);
    return along > 0 && vlen(vsub(d, vscale(dir, along))) <= sizes.radius;
  });
  let steps = kept;
  if (plan.ground0 !== null && plan.ground1 !== null) {
    steps = kept.filter(({ point }) => vlen(flat(vsub(point, ahead))) > sizes.step);
  } else if (plan.ground0 !== null && plan.confirmed) {
    steps = [...kept, { point: ahead, reason: plan.aheadSeen === null ? 'edge' : 'step' }];
  }
  const along = ({ point }) => vdot(vsub(point, origin), dir);
  return steps.sort((a, b) => along(a) - along(b)).slice(0, 16);
}

// The ground's height (up . point) a plan expects under world point `p`: from the ground under
// its origin to the ground `look` ahead, by how far p is along its direction; null when it knows
// none (or has not confirmed it).
export function walkGroundAt(plan, p, up) {
  const g0 = plan.ground0;
  if (!plan.confirmed || g0 === null) return null;
  if (!plan.dir || plan.ground1 === null) return g0;
  const s = vdot(vsub(p, plan.origin), plan.dir);
  const t = Math.max(0, Math.min(1, s / plan.look));
  return g0 + (plan.ground1 - g0) * t;
}

// One walk step (an animation frame of dt seconds): the camera at `position` wants to move
// `distance` along `dir` (unit, along the ground; null: standing). It moves only by what `plan`
// allows: in its direction (within 15 degrees; another direction waits for its own look), until
// its distance from the plan's origin along the plan's direction reaches `plan.allowed`, and not
// while the height is still settling (more than a fifth of an eye height off). Its height eases
// towards eye height above walkGroundAt (rising or falling at most 2 eye heights a second); an
// unconfirmed plan, or no ground, holds the height.
// Returns { position, moved (distance along the ground), blocked (a move was asked and the plan
// stops it at an obstacle, edge or step), waiting (a move was asked and waits for a look) }.
export function walkStep(position, dir, distance, up, sizes, plan, dt) {
  let p = position;
  let blocked = false;
  let waiting = false;
  let moved = 0;
  const h = vdot(p, up);
  const ground = plan ? walkGroundAt(plan, p, up) : null;
  const settled = ground === null || Math.abs(h - ground - sizes.eye) <= 0.2 * sizes.eye;
  if (dir && distance > 0) {
    const cos = plan && plan.dir ? vdot(dir, plan.dir) : -1;
    if (!plan || cos < Math.cos(Math.PI / 12) || !settled || plan.reason === 'check') {
      waiting = true;
    } else {
      const room = plan.allowed - vdot(vsub(p, plan.origin), plan.dir);
      let d = Math.max(0, Math.min(distance, room / cos));
      if (d < 1e-9) d = 0;
      if (d > 0) {
        p = vadd(p, vscale(dir, d));
        moved = d;
      }
      blocked = d < distance - 1e-12 && plan.reason !== '';
      waiting = d < distance - 1e-12 && plan.reason === '';
    }
  }
  const ground2 = plan ? walkGroundAt(plan, p, up) : null;
  if (ground2 !== null) {
    let target = ground2 + sizes.eye;
    // Rising, never through what the up probe saw: stop short of it by the stop distance.
    const h2 = vdot(p, up);
    if (target > h2 && plan.ceiling !== null && plan.ceiling !== undefined) target = Math.max(h2, Math.min(target, plan.ceiling - sizes.radius));
    const dh = target - h2;
    const most = 2 * sizes.eye * dt;
    // Within a ten-thousandth of the eye height it is there (no pose a frame for nothing).
    if (Math.abs(dh) > 1e-4 * sizes.eye) p = vadd(p, vscale(up, Math.max(-most, Math.min(most, dh * Math.min(1, dt * 8)))));
  }
  return { position: p, moved, blocked, waiting };
}

// The part of `v` along the ground (perpendicular to `up`).
export const alongGround = (v, up) => vsub(v, vscale(up, vdot(v, up)));
