// End-to-end test of VR tours (issue 94): the real catgs-server (CPU renderer, the bundled biker)
// and the real page in headless Chromium, with IWER (the Immersive Web Emulation Runtime, npm
// `iwer`) emulating a Meta Quest 3 in stereo, injected before the page's scripts. Steps:
//  - the page offers "Enter VR" (vrSupported) and a click enters: the stream is resized to both
//    eyes side by side (2 eyeW x eyeH, from the layer's viewports and ?scale), the headset's first
//    pose lands on the page's camera, and every pose sent carries both eyes (IPD apart, along the
//    head's right);
//  - the server answers with stereo frames: Frame.eye_width the eye's width, and both EyeViews,
//    which are the eyes of the pose the frame answers (each eye rendered as sent);
//  - a head path of turns and steps (IWER's headset pose driven each display frame), with frames
//    arriving throughout; the layer's pixels (both eyes) are saved as PNGs on the way
//    (vr_eyes_*.png) and the page's screenshot (vr_page.png);
//  - a head turn during a frame's round trip: with the newest frame on the display, the head turns
//    4 degrees and the very next display frame (before any frame for the turned pose) must show the
//    turned view: its pixels match the last frame's rotated by an independent homography (K R K^-1
//    from the view's own projection matrix, computed here in node) far better than the unturned
//    picture does;
//  - the disparity of the object at the centre between the two eyes' pictures matches its depth
//    (the server's depth probe): IPD fx / depth, within 1 px;
//  - leaving VR: the camera is at the head's last pose, the stream is resized back to the page's
//    size and flat frames of that size come again.
//
// usage: node vr_e2e_test.mjs --server PATH/catgs-server [--repo ROOT] [--out DIR] [--allow-mono 1]
// --allow-mono 1: a server that answers stereo poses with mono frames (one before stereo support)
// passes the checks that do not need stereo frames, and says which it left out.
// Exit codes: 0 pass, 1 fail, 77 skipped (no chromium / npm deps / server binary / iwer).
import { existsSync, mkdtempSync, readFileSync, writeFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';
import { BrowserTestRun, browserOrSkip, sleep, waitFor } from './harness.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const repo = path.resolve(args.repo || path.join(here, '../..'));
const serverBin = args.server || process.env.CATGS_SERVER;
const outDir = path.resolve(args.out || mkdtempSync(path.join(os.tmpdir(), 'catgs-vr-out-')));
const allowMono = args['allow-mono'] === '1';
const { chromium, chromiumPath } = browserOrSkip(here, { 'catgs-server': serverBin });
const iwerBundle = path.join(here, 'node_modules/iwer/build/iwer.min.js');
if (!existsSync(iwerBundle)) {
  console.log('SKIP: tests/e2e/node_modules/iwer is missing: run scripts/setup_web.sh');
  process.exit(77);
}
const require = createRequire(import.meta.url);
const { PNG } = require('pngjs');
const cam = await import(pathToFileURL(path.join(repo, 'web_client/viewer/camera.js')).href);

// The window (IWER sizes the XR layer's canvas to it: each eye half of it) and the page's render
// scale: eyes of 480x540 display pixels streamed at 240x270 each (the CPU renderer on 2 cores).
const VIEW = { width: 960, height: 540 };
const SCALE = 0.5;
const IPD = 0.063; // IWER's default, metres
const run = new BrowserTestRun('vr', { serverBin, webRoot: path.join(repo, 'web_client'), outDir });
const { log, check } = run;
const hook = (page, fn, arg) => page.evaluate(fn, arg);
const near = (a, b, eps) => a.length === b.length && a.every((v, i) => Math.abs(v - b[i]) <= eps);
const sameRotation = (a, b, eps) => Math.abs(Math.abs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]) - 1) <= eps;

// IWER before any of the page's scripts: a Quest 3 in stereo, replacing Chromium's own
// navigator.xr (which offers no immersive-vr headless), at window.xrDevice for the test to drive.
const INIT = `${readFileSync(iwerBundle, 'utf8')}
;(() => {
  const device = new IWER.XRDevice(IWER.metaQuest3, { stereoEnabled: true });
  device.installRuntime({ forceInstall: true });
  window.xrDevice = device;
})();`;

// A PNG data URL -> { width, height, data (RGBA) }.
const decodePng = (url) => PNG.sync.read(Buffer.from(url.slice(url.indexOf(',') + 1), 'base64'));

function savePng(url, file) {
  const f = path.join(outDir, file);
  writeFileSync(f, Buffer.from(url.slice(url.indexOf(',') + 1), 'base64'));
  log(`screenshot ${f}`);
}

// Drives the headset along `keys` ({ t (s), position [x, y, z] metres, yaw, pitch (degrees) }),
// one pose a display frame (linear between keys); resolves with what the page saw meanwhile.
function headPath(page, keys) {
  return hook(page, (ks) => new Promise((resolve) => {
    const d = window.xrDevice;
    const seen = { frames: new Set(), latencies: [], stereo: 0, eyeWidths: new Set(), posesSentBefore: window.catgs.vr.posesSent };
    const t0 = performance.now();
    const end = ks[ks.length - 1].t;
    const step = () => {
      const t = (performance.now() - t0) / 1000;
      let i = 0;
      while (i + 1 < ks.length - 1 && ks[i + 1].t <= t) i++;
      const a = ks[i];
      const b = ks[Math.min(i + 1, ks.length - 1)];
      const u = b.t > a.t ? Math.min(Math.max((t - a.t) / (b.t - a.t), 0), 1) : 1;
      const lerp = (x, y) => x + (y - x) * u;
      d.position.set(lerp(a.position[0], b.position[0]), lerp(a.position[1], b.position[1]), lerp(a.position[2], b.position[2]));
      const yaw = (lerp(a.yaw, b.yaw) * Math.PI) / 180;
      const pitch = (lerp(a.pitch, b.pitch) * Math.PI) / 180;
      // yaw about the room's up, then pitch about the head's right (XR axes: y up, -z forward).
      const qy = [Math.cos(yaw / 2), 0, Math.sin(yaw / 2), 0];
      const qx = [Math.cos(pitch / 2), Math.sin(pitch / 2), 0, 0];
      const w = qy[0] * qx[0];
      d.quaternion.set(qy[0] * qx[1], qy[2] * qx[0], -qy[2] * qx[1], w);
      const f = window.catgs.lastFrame;
      if (f && !seen.frames.has(f.sequence)) {
        seen.frames.add(f.sequence);
        if (Number.isFinite(f.latencyMs)) seen.latencies.push(f.latencyMs);
        if (f.eyeWidth > 0) {
          seen.stereo++;
          seen.eyeWidths.add(f.eyeWidth);
        }
      }
      if (t < end) requestAnimationFrame(step);
      else resolve({ frames: seen.frames.size, stereo: seen.stereo, eyeWidths: [...seen.eyeWidths], latencies: seen.latencies, posesSent: window.catgs.vr.posesSent - seen.posesSentBefore });
    };
    requestAnimationFrame(step);
  }), keys);
}

// Waits until the display shows the frame of the newest pose sent (the head still).
async function settled(page) {
  await waitFor('the frame of the newest pose on the display', () => hook(page, () => {
    const vr = window.catgs.vr;
    const p = window.catgs.lastPoseSent;
    const f = window.catgs.lastFrame;
    return vr && p && f && f.poseSequence >= p.sequence && vr.lastDraw && vr.lastDraw.length &&
      vr.lastDraw.every((d) => d.frameSequence === f.sequence);
  }), 30000, 50);
}

// The head still at `keyPose`; returns the capture of a display frame of its own frame.
async function stillShot(page, keyPose) {
  await headPath(page, [{ t: 0, ...keyPose }, { t: 0.05, ...keyPose }]);
  await settled(page);
  await sleep(100);
  return hook(page, () => window.catgs.vrCapture());
}

// The pinhole intrinsics of a view from its angles (stereo.js's rule, written again here).
function viewK(view) {
  const a = view.world.angles;
  const [tl, tr, tu, td] = [a.left, a.right, a.up, a.down].map(Math.tan);
  const fx = view.viewport.width / (tr - tl);
  const fy = view.viewport.height / (tu - td);
  return { fx, fy, cx: -tl * fx, cy: tu * fy };
}

// Mean absolute difference (RGB, 0..255) over the pixels of eye viewport `vp` of image `b` against
// image `a` sampled at map(x, y) (display pixel -> a's pixel in the same eye; null: not compared),
// where either shows something (the biker stands on black: the black around him would dilute it).
function compareEye(a, b, vp, H, map) {
  let sum = 0;
  let n = 0;
  const top = H - (vp.y + vp.height); // GL viewports count from the bottom
  for (let y = top + 8; y < top + vp.height - 8; y += 2) {
    for (let x = vp.x + 8; x < vp.x + vp.width - 8; x += 2) {
      const m = map(x - vp.x + 0.5, y - top + 0.5);
      if (!m) continue;
      const [u, v] = m;
      if (!(u >= 1 && v >= 1 && u < vp.width - 1 && v < vp.height - 1)) continue;
      const ax = Math.floor(vp.x + u);
      const ay = Math.floor(top + v);
      const ia = (ay * a.width + ax) * 4;
      const ib = (y * b.width + x) * 4;
      const lit = (d, i) => d[i] + d[i + 1] + d[i + 2] > 60;
      if (!lit(a.data, ia) && !lit(b.data, ib)) continue;
      for (let c = 0; c < 3; c++) sum += Math.abs(a.data[ia + c] - b.data[ib + c]);
      n += 3;
    }
  }
  return n ? { mad: sum / n, samples: n / 3 } : { mad: Infinity, samples: 0 };
}

// The centroid of the lit pixels of eye viewport `vp` (the biker), display pixels of the eye.
function litCentroid(img, vp) {
  const top = img.height - (vp.y + vp.height);
  let sx = 0;
  let sy = 0;
  let n = 0;
  for (let y = 0; y < vp.height; y++) {
    for (let x = 0; x < vp.width; x++) {
      const i = ((top + y) * img.width + vp.x + x) * 4;
      if (img.data[i] + img.data[i + 1] + img.data[i + 2] > 60) {
        sx += x;
        sy += y;
        n++;
      }
    }
  }
  return n ? [sx / n + 0.5, sy / n + 0.5] : null;
}

// Sub-pixel horizontal disparity of the left eye's patch around (cx, cy) in the right eye's image
// (rows of the same height: IWER's eyes are parallel), by the sum of absolute differences and a
// parabola through the best shift's neighbours.
function disparity(img, left, right, cx, cy, half = 12, maxShift = 60) {
  const H = img.height;
  const rowOf = (vp, y) => H - (vp.y + vp.height) + y;
  const at = (x, y, c) => img.data[(y * img.width + x) * 4 + c];
  const cost = (d) => {
    let s = 0;
    for (let y = Math.round(cy) - half; y <= Math.round(cy) + half; y++) {
      for (let x = Math.round(cx) - half; x <= Math.round(cx) + half; x++) {
        const xr = x - d;
        if (xr < 0 || xr >= right.width) return Infinity;
        for (let c = 0; c < 3; c++) s += Math.abs(at(left.x + x, rowOf(left, y), c) - at(right.x + xr, rowOf(right, y), c));
      }
    }
    return s;
  };
  const costs = [];
  for (let d = -4; d <= maxShift; d++) costs.push([d, cost(d)]);
  let best = 0;
  costs.forEach((c, i) => (c[1] < costs[best][1] ? (best = i) : 0));
  const [d0, c0] = costs[best];
  const cm = best > 0 ? costs[best - 1][1] : c0;
  const cp = best + 1 < costs.length ? costs[best + 1][1] : c0;
  const den = cm - 2 * c0 + cp;
  return d0 + (den > 0 ? (0.5 * (cm - cp)) / den : 0);
}

async function main(context) {
  const scene = path.join(repo, 'assets/scenes/biker.compressed.ply');
  const base = await run.startServer(['--scene', scene]);
  await context.addInitScript({ content: INIT });
  const page = await run.openPage(context, `${base}/?scale=${SCALE}`);
  const flat = await hook(page, () => ({ pose: window.catgs.pose(), viewport: window.catgs.viewport, welcome: window.catgs.welcome }));
  log(`flat: stream ${flat.viewport.width}x${flat.viewport.height}`);

  // ---- enter ----
  await waitFor('the Enter VR button', () => hook(page, () => !document.getElementById('btn-vr').hidden), 10000);
  check(true, 'the page offers Enter VR (IWER\'s Quest 3 supports immersive-vr)');
  await page.click('#btn-vr');
  await waitFor('VR to start', () => hook(page, () => window.catgs.vr && window.catgs.vr.active), 15000);
  // Before the first frame comes (a round trip, a render on the CPU): a plain dark grey, not black.
  const waiting = await hook(page, () => window.catgs.vrCapture());
  if (waiting.frames === 0) {
    const w = decodePng(waiting.png);
    const centre = [...w.data.subarray(((w.height >> 1) * w.width + (w.width >> 2)) * 4, ((w.height >> 1) * w.width + (w.width >> 2)) * 4 + 3)];
    check(near(centre, [31, 31, 36], 1), `before the first VR frame the headset shows dark grey (${centre})`);
  } else {
    log('(the first VR frame came before the first display frame: the waiting colour is not seen)');
  }
  await waitFor('VR display frames', () => hook(page, () => window.catgs.vr.xrFrames > 2), 15000);
  const first = await hook(page, () => window.catgs.vr);
  const eyeW = Math.floor((VIEW.width / 2) * SCALE / 2) * 2;
  const eyeH = Math.floor(VIEW.height * SCALE / 2) * 2;
  check(first.views && first.views.length === 2 && first.views[0].eye === 'left' && first.views[1].eye === 'right',
    `two views, left and right (${first.views && first.views.map((v) => `${v.eye} ${v.viewport.width}x${v.viewport.height}`).join(', ')})`);
  check(first.size && first.size.eyeWidth === eyeW && first.size.width === 2 * eyeW && first.size.height === eyeH,
    `the stream is resized to both eyes side by side: ${first.size && `${first.size.width}x${first.size.height}, eye ${first.size.eyeWidth}`} (want ${2 * eyeW}x${eyeH})`);
  const vp = await hook(page, () => window.catgs.viewport);
  check(vp.width === 2 * eyeW && vp.height === eyeH, `the viewer's viewport is the VR stream's (${vp.width}x${vp.height})`);
  // The first head pose lands on the page's camera (its forward levelled: the biker's first view
  // looks down a little).
  const up = [flat.welcome.up.x, flat.welcome.up.y, flat.welcome.up.z];
  const level = (v) => cam.vnorm(cam.vsub(v, cam.vscale(up, cam.vdot(v, up))));
  const f0 = level(cam.cameraForward(flat.pose.orientation));
  const fHead = cam.cameraForward(first.head.orientation);
  check(near(first.head.position, flat.pose.position, 1e-6), `the headset's first pose is at the page's camera (${first.head.position.map((v) => v.toFixed(3))})`);
  check(cam.vdot(fHead, f0) > 0.9999 && Math.abs(cam.vdot(fHead, up)) < 1e-6,
    `the head looks along the camera's level forward (cos ${cam.vdot(fHead, f0).toFixed(6)}, up component ${cam.vdot(fHead, up).toExponential(1)})`);
  const sent = await hook(page, () => window.catgs.lastPoseSent);
  const eyeGap = sent.leftEye && sent.rightEye ? cam.vsub(sent.rightEye.position, sent.leftEye.position) : null;
  check(sent.displayHz >= 24 && sent.displayHz <= 240, `the pose sent says the headset's display rate (${sent.displayHz} Hz: IWER's session frameRate)`);
  check(eyeGap && Math.abs(cam.vlen(eyeGap) - IPD) < 1e-6 && cam.vdot(cam.vnorm(eyeGap), cam.cameraRight(sent.orientation)) > 0.9999,
    `the pose sent carries both eyes, ${eyeGap ? cam.vlen(eyeGap).toFixed(4) : '-'} units apart along the head's right (IPD ${IPD} m, a unit taken as a metre)`);

  // ---- stereo frames ----
  const stereoSeen = await waitFor('a stereo frame', () => hook(page, () => {
    const f = window.catgs.lastFrame;
    return f && f.eyeWidth > 0 ? f : null;
  }), 20000, 100).catch(() => null);
  if (!stereoSeen) {
    const f = await hook(page, () => window.catgs.lastFrame);
    check(allowMono, `the server answers with stereo frames (last frame ${f && `${f.width}x${f.height} eye_width ${f.eyeWidth}`})`);
    log(`(mono server: frames of ${f && `${f.width}x${f.height}`} with eye_width 0; the stereo checks are left out)`);
  } else {
    check(stereoSeen.eyeWidth === eyeW && stereoSeen.width === 2 * eyeW && stereoSeen.height === eyeH,
      `stereo frame: ${stereoSeen.width}x${stereoSeen.height}, eye_width ${stereoSeen.eyeWidth}`);
    check(!!stereoSeen.leftEye && !!stereoSeen.rightEye, 'the frame names both eyes it shows (Frame.left_eye, right_eye)');
  }
  // A still head: the frame of the newest pose shows exactly the eyes sent.
  const START = { position: [0, 1.6, 0], yaw: 0, pitch: 0 };
  const shot0 = await stillShot(page, START);
  savePng(shot0.png, 'vr_eyes_start.png');
  const sent0 = await hook(page, () => window.catgs.lastPoseSent);
  if (stereoSeen) {
    const lf = shot0.lastFrame;
    const same = (e, s) => e && s && near(e.position, s.position, 1e-5) && sameRotation(e.orientation, s.orientation, 1e-6) &&
      near([e.angles.left, e.angles.right, e.angles.up, e.angles.down], [s.angles.left, s.angles.right, s.angles.up, s.angles.down], 1e-6);
    check(lf.poseSequence === sent0.sequence && same(lf.leftEye, sent0.leftEye) && same(lf.rightEye, sent0.rightEye),
      `the frame of pose ${sent0.sequence} shows the eyes that pose sent (frame eyes at ${lf.leftEye && lf.leftEye.position.map((v) => v.toFixed(4))} / ${lf.rightEye && lf.rightEye.position.map((v) => v.toFixed(4))})`);
  }

  // ---- a head path: turns and steps ----
  const PATH = [
    { t: 0, ...START },
    { t: 1.5, position: [0, 1.6, 0], yaw: 35, pitch: 0 }, // turn left
    { t: 3.5, position: [0, 1.6, 0], yaw: -35, pitch: -10 }, // turn right, look down a little
    { t: 5, position: [0, 1.6, 0], yaw: 0, pitch: 0 },
    { t: 6.5, position: [0, 1.6, -0.5], yaw: 0, pitch: 0 }, // a step forward (XR forward is -z)
    { t: 7.5, position: [0.3, 1.6, -0.5], yaw: 0, pitch: 0 }, // and to the right
    { t: 8.5, position: [0.3, 1.5, -0.5], yaw: 10, pitch: -5 }, // crouch a little, look left
  ];
  const walked = await headPath(page, PATH);
  const lat = walked.latencies.slice().sort((a, b) => a - b);
  const pct = (p) => (lat.length ? lat[Math.min(lat.length - 1, Math.floor(p * lat.length))].toFixed(1) : '-');
  log(`head path of ${PATH[PATH.length - 1].t} s: ${walked.posesSent} poses sent, ${walked.frames} frames (${walked.stereo} stereo, eye widths ${walked.eyeWidths.join(',') || '-'}), ` +
    `pose-to-frame latency p50 ${pct(0.5)} ms, p95 ${pct(0.95)} ms`);
  check(walked.frames >= 5, `frames arrive along the head path (${walked.frames})`);
  check(walked.posesSent >= 60, `a pose a display frame while the head moves (${walked.posesSent})`);
  if (stereoSeen) check(walked.stereo === walked.frames, `every frame on the path is stereo (${walked.stereo} of ${walked.frames})`);
  const END = PATH[PATH.length - 1];
  const shot1 = await stillShot(page, END);
  savePng(shot1.png, 'vr_eyes_after_path.png');
  await run.shot(page, 'vr_page.png');

  // ---- a head turn within a frame's round trip ----
  const TURN_DEG = 4;
  await stillShot(page, END);
  const pair = await hook(page, async (turnDeg) => {
    const before = await window.catgs.vrCapture();
    const d = window.xrDevice;
    // Turn left about the room's up by turnDeg, from the pose the head has.
    const a = (turnDeg * Math.PI) / 180;
    const q = d.quaternion;
    const [w, x, y, z] = [q.w, q.x, q.y, q.z];
    const r = [Math.cos(a / 2), 0, Math.sin(a / 2), 0];
    d.quaternion.set(r[0] * x + r[2] * z, r[0] * y + r[2] * w, r[0] * z - r[2] * x, r[0] * w - r[2] * y);
    const after = await window.catgs.vrCapture();
    return { before, after };
  }, TURN_DEG);
  const A = decodePng(pair.before.png);
  const B = decodePng(pair.after.png);
  savePng(pair.before.png, 'vr_turn_before.png');
  savePng(pair.after.png, 'vr_turn_after.png');
  const drawnA = pair.before.lastDraw[0].frameSequence;
  const drawnB = pair.after.lastDraw[0].frameSequence;
  check(drawnA === drawnB && pair.after.posesSent > pair.before.posesSent,
    `the display frame after the turn still shows frame ${drawnB} (the turned pose went out: ${pair.after.posesSent - pair.before.posesSent} pose(s), no answer yet)`);
  // The turn about the head's vertical axis, seen from each eye: the old picture's pixel under
  // display pixel p is K R^T K^-1 p (R: the eye's rotation by the turn, in its own axes: for a
  // level head, a turn left about -y of OpenCV axes); eyes 3 cm off the axis move by 2 mm: nothing
  // at the scene's depth.
  const a = (TURN_DEG * Math.PI) / 180;
  for (let i = 0; i < 2; i++) {
    const view = pair.after.views[i];
    const K = viewK(view);
    const Ka = viewK(pair.before.views[i]);
    // pitch of the head at END (XR pitch about x): the view's rotation in its own axes is the yaw
    // about the room's up expressed in the eye's frame; take it from the two orientations instead.
    const qa = pair.before.views[i].world.orientation;
    const qb = view.world.orientation;
    const rel = cam.qmul([qa[0], -qa[1], -qa[2], -qa[3]], qb); // after, in before's axes
    const map = (x, y) => {
      const ray = cam.qrotate(rel, [(x - K.cx) / K.fx, (y - K.cy) / K.fy, 1]);
      if (!(ray[2] > 1e-6)) return null;
      return [Ka.fx * (ray[0] / ray[2]) + Ka.cx, Ka.fy * (ray[1] / ray[2]) + Ka.cy];
    };
    const turned = compareEye(A, B, view.viewport, B.height, map);
    const unturned = compareEye(A, B, view.viewport, B.height, (x, y) => [x, y]);
    const angle = 2 * Math.acos(Math.min(1, Math.abs(rel[0]))) * 180 / Math.PI;
    log(`${view.eye} eye: turned ${angle.toFixed(2)} deg; the display vs the last picture turned: ${turned.mad.toFixed(2)} mean abs diff ` +
      `(${turned.samples} px), vs not turned: ${unturned.mad.toFixed(2)}`);
    check(Math.abs(angle - TURN_DEG) < 0.01, `${view.eye} eye turned by ${angle.toFixed(3)} deg`);
    check(unturned.mad > 4 && turned.mad < 0.35 * unturned.mad,
      `${view.eye} eye: the next display frame shows the turned view (re-projected): ${turned.mad.toFixed(2)} vs ${unturned.mad.toFixed(2)} unturned`);
  }

  // ---- disparity against depth ----
  // A step towards the biker (about 1.9 units away then): his picture in the two eyes is shifted by
  // IPD fx / depth. Measured at the middle of his lit pixels in the left eye (a block match along
  // the row in the right eye), against the server's depth probe through that pixel of the left
  // eye's frame (IWER's eyes are symmetric: a vertical field of view and the eye's size say it).
  if (stereoSeen) {
    const NEAR = { position: [0.1, 1.6, -1.5], yaw: 0, pitch: -5 };
    await headPath(page, [{ t: 0, ...END }, { t: 1, ...NEAR }]);
    const still = await stillShot(page, NEAR);
    savePng(still.png, 'vr_eyes_near.png');
    const img = decodePng(still.png);
    const [L, R] = still.views;
    const K = viewK(L);
    const c = litCentroid(img, L.viewport);
    const le = still.lastFrame.leftEye;
    const vfov = ((le.angles.up - le.angles.down) * 180) / Math.PI;
    const k = still.lastFrame.eyeWidth / L.viewport.width; // display -> stream pixels (the head is still: a scale)
    const res = c && await hook(page, ({ pose, w, h, x, y }) => window.catgs.probePose(pose, w, h, x, y).then((r) => ({ hit: r.hit, depth: r.depth })),
      { pose: { position: le.position, orientation: le.orientation, fovDeg: vfov }, w: still.lastFrame.eyeWidth, h: still.lastFrame.height, x: c[0] * k, y: c[1] * k });
    if (!res || !res.hit) {
      check(false, `the depth probe sees a surface under the biker's middle in the left eye (${c && c.map((v) => v.toFixed(1))})`);
    } else {
      const baseline = cam.vlen(cam.vsub(still.lastFrame.rightEye.position, le.position));
      const want = (K.fx * baseline) / res.depth;
      const got = disparity(img, L.viewport, R.viewport, c[0], c[1]);
      log(`disparity at (${c.map((v) => v.toFixed(0))}) of the left eye: ${got.toFixed(2)} px measured, ${want.toFixed(2)} px from the depth ${res.depth.toFixed(3)} ` +
        `(baseline ${baseline.toFixed(4)}, fx ${K.fx.toFixed(1)} display px)`);
      check(Math.abs(got - want) <= 1, `the eyes' disparity matches the depth within 1 px (${got.toFixed(2)} vs ${want.toFixed(2)})`);
    }
  } else {
    log('(mono server: the disparity check is left out)');
  }

  // ---- the thumbstick: a smooth step along the head's level forward ----
  // IWER's left Touch controller held forward for a second: the visitor moves (the anchor), not
  // the headset in the room; no scale: a quarter of the scene scale a second.
  const before = await hook(page, () => window.catgs.vr);
  await hook(page, () => window.xrDevice.controllers.left.updateAxes('thumbstick', 0, -1));
  await sleep(1000);
  await hook(page, () => window.xrDevice.controllers.left.updateAxes('thumbstick', 0, 0));
  await sleep(200);
  const after = await hook(page, () => window.catgs.vr);
  const walkedBy = cam.vsub(after.head.position, before.head.position);
  const lvlFwd = level(cam.cameraForward(before.head.orientation));
  const speed = flat.welcome.scene_scale / 4;
  log(`thumbstick forward for 1 s: the head moved ${cam.vlen(walkedBy).toFixed(3)} units (the stick's steps add up to ${(after.moved - before.moved).toFixed(3)}; ${speed.toFixed(3)} units/s)`);
  check(cam.vlen(walkedBy) > 0.5 * speed && cam.vlen(walkedBy) < 1.5 * speed && cam.vdot(cam.vnorm(walkedBy), lvlFwd) > 0.999,
    `the thumbstick moves the visitor along the head's level forward (${cam.vlen(walkedBy).toFixed(3)} units, cos ${cam.vdot(cam.vnorm(walkedBy), lvlFwd).toFixed(5)})`);

  // ---- leave ----
  const last = await hook(page, () => window.catgs.vr.head);
  await hook(page, () => window.catgs.exitVr());
  await waitFor('VR to end', () => hook(page, () => window.catgs.vr === null), 10000);
  const back = await hook(page, () => ({ pose: window.catgs.pose(), viewport: window.catgs.viewport }));
  check(near(back.pose.position, last.position, 1e-9) && sameRotation(back.pose.orientation, last.orientation, 1e-9),
    `left VR: the camera is at the head's last pose (${back.pose.position.map((v) => v.toFixed(3))})`);
  check(back.viewport.width === flat.viewport.width && back.viewport.height === flat.viewport.height,
    `the stream is the page's size again (${back.viewport.width}x${back.viewport.height})`);
  const flatAgain = await waitFor('a flat frame of the page\'s size', () => hook(page, (v) => {
    const f = window.catgs.lastFrame;
    const p = window.catgs.lastPoseSent;
    return f && f.width === v.width && f.height === v.height && f.eyeWidth === 0 && f.poseSequence >= p.sequence && !p.leftEye ? f : null;
  }, flat.viewport), 30000, 100).catch(() => null);
  check(!!flatAgain, `the flat stream resumes at the page's size${flatAgain ? ` (frame ${flatAgain.sequence}, ${flatAgain.width}x${flatAgain.height})` : ''}`);
  await sleep(300);
  await run.shot(page, 'vr_after_exit.png');
  const errors = await hook(page, () => window.catgs.errors);
  check(errors.length === 0, `no error events (${errors.map((e) => e.name).join(', ') || 'none'})`);

  // ---- the <catgs-viewer> element: its own Enter VR button ----
  // An element added to this page (the module is loaded: the element is defined) opens a session of
  // its own; its button shows (IWER offers immersive-vr) and takes it into VR and out again.
  await hook(page, () => {
    const el = document.createElement('catgs-viewer');
    el.id = 'element-under-test';
    el.style.cssText = 'position:fixed;left:10px;bottom:10px;width:320px;height:180px;z-index:5';
    el.vrEvents = [];
    el.addEventListener('vr', (e) => el.vrEvents.push(e.detail.active));
    document.body.append(el);
  });
  // It asks whether VR is there once the visitor points at it (viewer.js _askVrOnce).
  await waitFor('the element\'s first frame', () => hook(page, () => document.getElementById('element-under-test').framesDecoded > 0), 60000, 100);
  await page.locator('#element-under-test').hover();
  await waitFor('the element\'s first frame and its button', () => hook(page, () => {
    const el = document.getElementById('element-under-test');
    const b = el.shadowRoot.querySelector('button.vr'); // made only where immersive VR is offered
    return el.framesDecoded > 0 && b && b.textContent === 'Enter VR';
  }), 60000, 100);
  check(true, 'the <catgs-viewer> element shows its Enter VR button once pointed at');
  await page.locator('#element-under-test').locator('button.vr').click();
  const elementVr = await waitFor('the element in VR with a stereo frame', () => hook(page, () => {
    const v = document.getElementById('element-under-test').viewer;
    const f = v.lastFrame;
    return v.vr && f && (f.eyeWidth > 0 || v.vr.snapshot().frames > 0) ? { eyeWidth: f.eyeWidth, frames: v.vr.snapshot().frames } : null;
  }), 30000, 100).catch(() => null);
  check(!!elementVr && (elementVr.eyeWidth > 0 || allowMono), `the element's button enters VR (${elementVr ? `eye_width ${elementVr.eyeWidth}` : 'no VR frame'})`);
  await hook(page, () => document.getElementById('element-under-test').exitVr());
  const elementBack = await hook(page, () => {
    const el = document.getElementById('element-under-test');
    const r = { events: el.vrEvents, vr: el.viewer.vr, label: el.shadowRoot.querySelector('button.vr').textContent };
    el.remove();
    return r;
  });
  check(elementBack.vr === null && elementBack.events.join() === 'true,false' && elementBack.label === 'Enter VR',
    `the element leaves VR: vr events ${elementBack.events.join(', ')}, its button says "${elementBack.label}"`);
}

process.exit(await run.main(chromium, chromiumPath, { viewport: VIEW }, main));
