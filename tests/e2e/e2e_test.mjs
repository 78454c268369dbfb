// End-to-end test: the real catgs-server (CPU renderer, bundled biker scene) serves web_client/;
// headless Debian Chromium (driven by playwright-core) loads the page, which offers AV1 where its
// WebCodecs decodes it; the first server streams AV1 to it (--av1 on), and the canvas at a fixed
// pose must match catgs-render's CPU image of that pose (PSNR >= 25 dB: the stream is lossy, the
// reference is exact). Then the viewer's features against the real server: a shared link opened
// with ?codec=h264 shows its view from an H.264 stream (compared with catgs-render of that
// pose), a recorded path exported as cameras.json replays through catgs-loadgen (and its first
// view, read back by catgs-render, is the pose the page sent), the same path exported as our
// .trace is read by catgs-render (one image per pose; first and last pose as sent) and replayed by
// catgs-loadgen, a second server with --token and --max-sessions 1 gives the token prompt and the
// full-server retry, and a third with --adaptive-quality on shows narrower frames under a pose
// flood (catgs_quality_down_total rises), a full-size refine frame once the camera stops, and
// full-size frames again under slow poses (catgs_quality_up_total rises); a fourth serves two
// scenes (the bundled biker and flowers_sh3 from the data folder): the page's scene picker lists
// both, and choosing the second reopens the page on it, showing that scene's render of the pose;
// a fifth is stopped with Ctrl-C and started again: the page says "server stopping" meanwhile and
// streams again within 2 s of its return.
//
// usage: node e2e_test.mjs --server PATH/catgs-server --render PATH/catgs-render
//                          [--loadgen PATH/catgs-loadgen] [--repo ROOT] [--data DIR]
//                          [--out DIR] [--min-psnr 25] [--frames 30]
// (or CATGS_SERVER / CATGS_RENDER / CATGS_LOADGEN / CATGS_DATA_DIR / CATGS_E2E_OUT in the
// environment; the data folder, by default ../shared/data beside the checkout, is optional: without
// its scenes/flowers_sh3.ply the scene picker step is skipped and says why)
// Exit codes: 0 pass, 1 fail, 77 skipped (no chromium / npm deps / binaries; the reason is printed).
import { spawn, spawnSync } from 'node:child_process';
import { existsSync, mkdirSync, mkdtempSync, readFileSync, readdirSync, rmSync, writeFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { freePort, sleep, stopServers, waitFor } from './harness.mjs';

const SKIP = 77;
const here = path.dirname(fileURLToPath(import.meta.url));
const CHROMIUM = process.env.CATGS_CHROMIUM || '/usr/bin/chromium';

function parseArgs(argv) {
  const a = {};
  for (let i = 0; i < argv.length; i++) {
    const k = argv[i];
    if (!k.startsWith('--')) throw new Error(`unexpected argument ${k}`);
    a[k.slice(2)] = argv[++i];
  }
  return a;
}
const args = parseArgs(process.argv.slice(2));
const repo = path.resolve(args.repo || process.env.CATGS_REPO || path.join(here, '../..'));
const serverBin = args.server || process.env.CATGS_SERVER;
const renderBin = args.render || process.env.CATGS_RENDER;
const loadgenBin = args.loadgen || process.env.CATGS_LOADGEN || '';
const outDir = path.resolve(args.out || process.env.CATGS_E2E_OUT || mkdtempSync(path.join(os.tmpdir(), 'catgs-e2e-out-')));
const minPsnr = Number(args['min-psnr'] || 25);
const minFrames = Number(args.frames || 30);
const scene = args.scene || path.join(repo, 'assets/scenes/biker.compressed.ply');
const dataDir = path.resolve(args.data || process.env.CATGS_DATA_DIR || path.join(repo, '../shared/data'));
const webRoot = path.join(repo, 'web_client');
const VIEW = { width: 480, height: 360 }; // small: the CPU renderer keeps up

const log = (...m) => console.log('[e2e]', ...m);
function skip(reason) {
  console.log(`SKIP: ${reason}`);
  process.exit(SKIP);
}

// ---- preconditions: skip (not fail) when the environment cannot run the test at all ----
if (!existsSync(CHROMIUM)) skip(`${CHROMIUM} is missing (apt-get install chromium)`);
if (!existsSync(path.join(here, 'node_modules/playwright-core')) || !existsSync(path.join(here, 'node_modules/pngjs'))) {
  skip('tests/e2e/node_modules is missing: run scripts/setup_web.sh');
}
if (!serverBin || !existsSync(serverBin)) skip(`catgs-server binary not given or missing (${serverBin || '--server'})`);
if (!renderBin || !existsSync(renderBin)) skip(`catgs-render binary not given or missing (${renderBin || '--render'})`);
// These are the project's own files: their absence is a failure, not a skip.
for (const f of ['index.html', 'app.js', 'viewer/vendor/protobuf.min.js', 'viewer/catgs_stream.proto']) {
  if (!existsSync(path.join(webRoot, f))) {
    console.error(`FAIL: web_client/${f} is missing (run scripts/setup_web.sh)`);
    process.exit(1);
  }
}
if (!existsSync(scene)) {
  console.error(`FAIL: scene ${scene} is missing`);
  process.exit(1);
}

const require = createRequire(import.meta.url);
const { chromium } = require('playwright-core');
const { PNG } = require('pngjs');


function psnrRgb(a, b) {
  if (a.width !== b.width || a.height !== b.height) throw new Error(`size mismatch ${a.width}x${a.height} vs ${b.width}x${b.height}`);
  let se = 0;
  for (let i = 0; i < a.data.length; i += 4) {
    for (let c = 0; c < 3; c++) {
      const d = a.data[i + c] - b.data[i + c];
      se += d * d;
    }
  }
  const mse = se / (a.width * a.height * 3);
  return mse === 0 ? Infinity : 10 * Math.log10((255 * 255) / mse);
}

// PSNR over the pixels where either image shows something (the biker sits on a black
// background, which makes the whole-image number generous).
function psnrForeground(a, b, threshold = 16) {
  let se = 0;
  let n = 0;
  for (let i = 0; i < a.data.length; i += 4) {
    const fg = Math.max(a.data[i], a.data[i + 1], a.data[i + 2], b.data[i], b.data[i + 1], b.data[i + 2]) > threshold;
    if (!fg) continue;
    n++;
    for (let c = 0; c < 3; c++) {
      const d = a.data[i + c] - b.data[i + c];
      se += d * d;
    }
  }
  return { psnr: se === 0 ? Infinity : 10 * Math.log10((255 * 255 * n * 3) / se), fraction: n / (a.width * a.height) };
}

// catgs-render's CPU image of `sceneFile` at `pose` ({ position, orientation [w, x, y, z], fovDeg },
// as the page's hook takes it), width x height, with the intrinsics Camera::from_pose derives
// (square pixels, principal point at the centre); returns the PNG's path in outDir.
function renderPose(sceneFile, name, pose, width, height) {
  const f = height / (2 * Math.tan((pose.fovDeg * Math.PI) / 360));
  const g = (v) => v.toPrecision(17);
  const trace = path.join(outDir, `${name}.trace`);
  writeFileSync(trace, `catgs-trace 1\n0 ${[...pose.position, ...pose.orientation, f, f, width / 2, height / 2].map(g).join(' ')} ${width} ${height}\n`);
  const out = path.join(outDir, `${name}.png`);
  const r = spawnSync(renderBin, ['--scene', sceneFile, '--trace', trace, '--out', out, '--renderer', 'cpu'], { encoding: 'utf8' });
  if (r.status !== 0) throw new Error(`catgs-render failed (${r.status}): ${r.stderr}${r.stdout}`);
  return out;
}

const failures = [];
function check(ok, what) {
  log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
  if (!ok) failures.push(what);
}

let server = null;
let serverLog = '';
let context = null;
const profileDir = mkdtempSync(path.join(os.tmpdir(), 'catgs-e2e-chromium-'));
const pageLog = [];

const servers = [];
// Starts catgs-server on `fixedPort` (0: a free port) with `extra` arguments; resolves once it
// serves HTTP.
async function startServer(extra = [], fixedPort = 0) {
  const port = fixedPort || (await freePort());
  // The bundled scene is under --lod-min-gaussians: its level of detail built all the same (the
  // overlay's LOD check below); derived files in the test's own cache folder.
  const serverArgs = ['--scene', scene, '--port', String(port), '--renderer', 'cpu', '--web-root', webRoot,
    '--lod-min-gaussians', '0', '--cache-dir', path.join(os.tmpdir(), 'catgs-e2e-cache'), ...extra];
  log(`starting ${serverBin} ${serverArgs.join(' ')}`);
  const proc = spawn(serverBin, serverArgs, { stdio: ['ignore', 'pipe', 'pipe'] });
  servers.push(proc);
  proc.stdout.on('data', (d) => (serverLog += d));
  proc.stderr.on('data', (d) => (serverLog += d));
  let serverExit = null;
  proc.on('exit', (code, sig) => (serverExit = `exited with ${code ?? sig}`));
  const base = `http://127.0.0.1:${port}`;
  await waitFor('the server to answer HTTP', async () => {
    if (serverExit) throw new Error(`catgs-server ${serverExit} before serving`);
    try {
      const r = await fetch(`${base}/`);
      return r.ok;
    } catch (_) {
      return false;
    }
  }, 60000, 200);
  log(`server up on ${base}`);
  return { proc, port, base };
}

async function run() {
  mkdirSync(outDir, { recursive: true });
  // AV1 forced on: the page's stream is AV1 whatever the machine's cores (the policy's auto would
  // pick it by them); the shared link below asks for H.264, so both codecs are decoded here.
  const first = await startServer(['--av1', 'on']);
  server = first.proc;
  const { port, base } = first;

  context = await chromium.launchPersistentContext(profileDir, {
    executablePath: CHROMIUM,
    headless: true,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
    viewport: VIEW,
    deviceScaleFactor: 1,
  });
  const page = context.pages()[0] || (await context.newPage());
  page.on('console', (m) => pageLog.push(`console.${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => pageLog.push(`pageerror: ${e.message}`));
  // Nothing may come from outside the server (no CDN at run time).
  const foreign = [];
  page.on('request', (r) => {
    const u = r.url();
    if (!u.startsWith(base) && !u.startsWith(`ws://127.0.0.1:${port}`) && !u.startsWith('data:')) foreign.push(u);
  });

  await page.goto(`${base}/?stats=1`);
  await page.waitForFunction(() => window.catgs && window.catgs.connected, null, { timeout: 30000 });
  const welcome = await page.evaluate(() => window.catgs.welcome);
  log(`welcome: scene=${welcome.scene_name} renderer=${welcome.renderer} encoder=${welcome.encoder} ` +
    `pipeline=${welcome.pipeline} ${welcome.width}x${welcome.height}`);
  check(welcome.renderer === 'cpu', `Welcome.renderer is cpu (${welcome.renderer})`);
  const offered = await page.evaluate(() => window.catgs.codecs);
  log(`codecs offered in Hello: ${JSON.stringify(offered)} (1 H.264, 2 AV1)`);
  check(offered.includes(2) && offered.includes(1), 'headless Chromium\'s WebCodecs decodes AV1 and H.264: the page offers both');
  check(welcome.codec === 2 && welcome.encoder === 'av1', `an AV1 stream to the page (Welcome codec ${welcome.codec}, encoder ${welcome.encoder})`);
  check(welcome.scene_scale > 0 && welcome.up && Math.abs(Math.hypot(welcome.up.x, welcome.up.y, welcome.up.z) - 1) < 1e-5,
    `Welcome carries the frame to navigate in (scale ${welcome.scene_scale}, up ${JSON.stringify(welcome.up)})`);
  const viewport = await page.evaluate(() => window.catgs.viewport);
  check(viewport.width === VIEW.width && viewport.height === VIEW.height, `Hello viewport ${viewport.width}x${viewport.height}`);

  // Stream: move the camera a little each tick through the hook so the server keeps rendering.
  const ip = welcome.initial_pose;
  const p0 = [ip.position.x, ip.position.y, ip.position.z];
  const q0 = [ip.orientation.w, ip.orientation.x, ip.orientation.y, ip.orientation.z];
  const fov0 = ip.vertical_fov_deg;
  const b = welcome.scene_bounds;
  const scale = Math.hypot(b.max.x - b.min.x, b.max.y - b.min.y, b.max.z - b.min.z) || 1;
  const t0 = Date.now();
  let i = 0;
  await waitFor(`${minFrames} decoded frames`, async () => {
    const d = 0.01 * scale * Math.sin(++i * 0.2);
    return page.evaluate(([p, q, f, dd, n]) => {
      window.catgs.setPose([p[0] + dd, p[1], p[2]], q, f);
      return window.catgs.framesDecoded >= n;
    }, [p0, q0, fov0, d, minFrames]);
  }, 240000, 50);
  const streamS = (Date.now() - t0) / 1000;
  const decoded = await page.evaluate(() => window.catgs.framesDecoded);
  log(`${decoded} frames decoded in ${streamS.toFixed(1)} s while moving (${(decoded / streamS).toFixed(1)} fps)`);

  // Fixed pose: the server's initial view. Wait for the frame that answers it, then let the stream
  // settle briefly (the server may send more frames of the same pose) and take the canvas.
  const seq = await page.evaluate(([p, q, f]) => window.catgs.setPose(p, q, f), [p0, q0, fov0]);
  check(Number.isInteger(seq) && seq > 0, `fixed pose sent with sequence ${seq}`);
  await page.waitForFunction((s) => window.catgs.lastFrame && window.catgs.lastFrame.poseSequence >= s, seq, { timeout: 30000 });
  await sleep(500);
  let shot = await page.evaluate(() => ({ frame: window.catgs.lastFrame, png: window.catgs.snapshot(), overlay: window.catgs.overlayText() }));
  check(shot.frame.poseSequence === seq, `last frame answers pose ${seq} (got ${shot.frame.poseSequence})`);
  log(`frame answering pose ${seq}: ${shot.frame.keyFrame ? 'key' : 'delta'} frame ${shot.frame.sequence}`);
  if (!shot.frame.keyFrame) {
    // A P-frame right after motion can be soft; an IDR of the same pose is the fairest picture.
    // The hook sends KeyFrameRequest and the same pose again (new sequence).
    const seq2 = await page.evaluate(() => window.catgs.requestKeyFrame());
    const gotKey = await page
      .waitForFunction((s) => { const f = window.catgs.lastFrame; return f.poseSequence >= s; }, seq2, { timeout: 30000 })
      .then(() => true, () => false);
    if (gotKey) shot = await page.evaluate(() => ({ frame: window.catgs.lastFrame, png: window.catgs.snapshot(), overlay: window.catgs.overlayText() }));
    check(gotKey && shot.frame.poseSequence === seq2, `the same pose re-sent as ${seq2} after a KeyFrameRequest is answered`);
    check(shot.frame.keyFrame, `... by a key frame (frame ${shot.frame.sequence})`);
  }
  const { width, height } = shot.frame;
  const streamedPath = path.join(outDir, 'streamed.png');
  writeFileSync(streamedPath, Buffer.from(shot.png.split(',')[1], 'base64'));

  // Reference: catgs-render of the same pose, with the intrinsics Camera::from_pose derives.
  const render = (name, position) => renderPose(scene, name, { position, orientation: q0, fovDeg: fov0 }, width, height);
  const refPath = render('reference', p0);
  const streamed = PNG.sync.read(readFileSync(streamedPath));
  const reference = PNG.sync.read(readFileSync(refPath));
  const psnr = psnrRgb(streamed, reference);
  const fg = psnrForeground(streamed, reference);
  log(`PSNR streamed vs catgs-render: ${psnr.toFixed(2)} dB (${width}x${height}); ` +
    `over the ${(100 * fg.fraction).toFixed(1)}% non-black pixels: ${fg.psnr.toFixed(2)} dB`);
  log(`images: ${streamedPath} ${refPath}`);
  check(fg.fraction > 0.02, 'the reference image shows the scene (> 2% non-black pixels)');
  check(psnr >= minPsnr, `PSNR ${psnr.toFixed(2)} dB >= ${minPsnr} dB`);
  // Negative control: the same view shifted sideways by 2% of the scene size must match clearly
  // worse, so a pass means the page sent this pose (not merely "some image of the scene").
  const right = [1 - 2 * (q0[2] ** 2 + q0[3] ** 2), 2 * (q0[1] * q0[2] + q0[0] * q0[3]), 2 * (q0[1] * q0[3] - q0[0] * q0[2])];
  const shiftedPath = render('shifted', p0.map((v, k) => v + 0.02 * scale * right[k]));
  const psnrShifted = psnrRgb(streamed, PNG.sync.read(readFileSync(shiftedPath)));
  log(`PSNR streamed vs a view shifted by 2% of the scene: ${psnrShifted.toFixed(2)} dB`);
  check(psnrShifted < psnr - 3, 'the streamed frame matches its own pose better than a shifted one (by > 3 dB)');

  // The frame's depth grid (issue 91: exact frames carry one, --depth-grid 32): the depth under a
  // vertex read on the page without a round trip agrees with the server's depth probe (its own
  // walk over every Gaussian) within the grid's one-byte inverse-depth code; the WebGL mesh canvas
  // that warps the frame by it is over the view.
  const depthCheck = await page.evaluate(async () => {
    const c = document.getElementById('view');
    // The vertices around the centre (multiples of 32): the first the probe finds a surface under.
    for (const [vx, vy] of [[224, 192], [256, 192], [224, 160], [256, 160], [224, 224], [256, 224], [192, 192], [288, 192]]) {
      const [x, y] = [vx * (c.clientWidth / c.width), vy * (c.clientHeight / c.height)];
      const probe = await window.catgs.probe(x, y);
      if (probe.hit) return { at: [vx, vy], grid: window.catgs.frameDepthAt(x, y), probe: probe.depth, mesh: !!document.querySelector('#view + canvas') };
    }
    return { grid: null, probe: null, mesh: !!document.querySelector('#view + canvas') };
  });
  log(`depth under a vertex: ${JSON.stringify(depthCheck)}`);
  check(depthCheck.probe !== null && depthCheck.grid !== null && Math.abs(depthCheck.grid - depthCheck.probe) <= 0.1 * depthCheck.probe,
    `the frame's depth grid reads the probe's depth within 10% (${JSON.stringify(depthCheck)})`);
  check(depthCheck.mesh, 'the depth warp\'s WebGL canvas is over the view');

  // Overlay: sane numbers and the session's facts.
  log(`overlay:\n${shot.overlay.replace(/^/gm, '    ')}`);
  const fpsMatch = /FPS (\d+(\.\d)?)/.exec(shot.overlay);
  check(!!fpsMatch && Number(fpsMatch[1]) > 0, `overlay shows a positive FPS (${fpsMatch && fpsMatch[1]})`);
  check(/latency \d+ ms/.test(shot.overlay), 'overlay shows a latency in ms');
  check(shot.overlay.includes(`frame ${width}x${height}`), `overlay shows the frame size ${width}x${height}`);
  check(/frame \d+x\d+ +av01\./.test(shot.overlay), 'overlay shows the AV1 codec string the decoder was configured with');
  check(shot.overlay.includes('renderer cpu') && shot.overlay.includes(`encoder ${welcome.encoder}`), 'overlay shows renderer and encoder');
  check(!/error/i.test(shot.overlay), 'overlay shows no error');
  // The scene is served with its level of detail (--lod write, the default; issue 46): the stats
  // say the bound the frames drew at and the Gaussians they drew.
  const lodMatch = /LOD (\d+\.\d) px {2}(\d+\.\d\d) M splats/.exec(shot.overlay);
  check(!!lodMatch && Number(lodMatch[1]) > 0 && Number(lodMatch[2]) > 0,
    `overlay shows the LOD bound and Gaussians a frame (${lodMatch && lodMatch[0]})`);
  const decoderErrors = await page.evaluate(() => window.catgs.decoderErrors);
  check(decoderErrors === 0, `no decoder errors (${decoderErrors})`);
  check(foreign.length === 0, `no request outside the server (${foreign.join(', ') || 'none'})`);
  const last = await page.evaluate(() => window.catgs.lastPoseSent);
  check(last && last.sequence === shot.frame.poseSequence, 'lastPoseSent reports the fixed pose');
  log(`frames decoded: ${await page.evaluate(() => window.catgs.framesDecoded)}`);

  // ---- A shared link shows its view: a new page opened with the shifted pose in its address
  // must match catgs-render's image of that pose (and not the unshifted one).
  const shifted = p0.map((v, k) => v + 0.02 * scale * right[k]);
  const linkPage = await context.newPage();
  linkPage.on('console', (m) => pageLog.push(`link console.${m.type()}: ${m.text()}`));
  await linkPage.goto(`${base}/?codec=h264&pos=${shifted.join(',')}&rot=${q0.join(',')}&fov=${fov0}`);
  await linkPage.waitForFunction(() => window.catgs && window.catgs.connected, null, { timeout: 30000 });
  const linkWelcome = await linkPage.evaluate(() => window.catgs.welcome);
  check(linkWelcome.codec === 1, `?codec=h264 offers H.264 alone and gets an H.264 stream (Welcome codec ${linkWelcome.codec})`);
  const linkSeq = await linkPage.evaluate(() => window.catgs.requestKeyFrame());
  await linkPage.waitForFunction((s) => window.catgs.lastFrame && window.catgs.lastFrame.poseSequence >= s && window.catgs.lastFrame.keyFrame,
    linkSeq, { timeout: 30000 });
  const linkPng = PNG.sync.read(Buffer.from((await linkPage.evaluate(() => window.catgs.snapshot())).split(',')[1], 'base64'));
  writeFileSync(path.join(outDir, 'link_view.png'), PNG.sync.write(linkPng));
  const linkVsShifted = psnrRgb(linkPng, PNG.sync.read(readFileSync(shiftedPath)));
  const linkVsStart = psnrRgb(linkPng, reference);
  log(`shared link view: PSNR vs catgs-render of the link's pose ${linkVsShifted.toFixed(2)} dB, vs the start view ${linkVsStart.toFixed(2)} dB`);
  check(linkVsShifted >= minPsnr && linkVsShifted > linkVsStart + 3, 'a shared link opens on its view (matches its pose\'s render, not the start view)');
  const shared = await linkPage.evaluate(() => window.catgs.shareUrl());
  check(new URL(shared).searchParams.get('pos').split(',').every((v, k) => Math.abs(Number(v) - shifted[k]) <= 1e-6 * scale),
    `the page's own link carries the same position (${shared})`);
  await linkPage.close();

  // ---- A recorded path exported as cameras.json replays through catgs-loadgen. The recording
  // starts at the fixed pose: the file's view 0, read by the core's reader in catgs-render, must
  // render the same image as that pose's trace.
  await page.evaluate(([p, q, f]) => window.catgs.setPose(p, q, f), [p0, q0, fov0]);
  await page.evaluate(() => window.catgs.toggleRecording());
  for (let k = 1; k <= 12; k++) {
    await page.evaluate(([p, q, f, d]) => window.catgs.setPose([p[0] + d, p[1], p[2] + d], q, f), [p0, q0, fov0, 0.004 * scale * k]);
    await sleep(100);
  }
  await page.evaluate(() => window.catgs.toggleRecording());
  const camerasJson = await page.evaluate(() => window.catgs.exportCameras('path'));
  const camerasPath = path.join(outDir, 'recorded_cameras.json');
  writeFileSync(camerasPath, camerasJson || '');
  const views = JSON.parse(camerasJson || '[]');
  check(views.length >= 3, `the recording (1.2 s) exports as ${views.length} cameras.json views (one per 0.5 s)`);
  const view0 = path.join(outDir, 'recorded_view0.png');
  const rv = spawnSync(renderBin, ['--scene', scene, '--cameras', camerasPath, '--view', '0', '--out', view0, '--renderer', 'cpu'], { encoding: 'utf8' });
  check(rv.status === 0, `catgs-render reads the exported cameras.json (${rv.status}: ${rv.stderr.trim().split('\n').pop()})`);
  if (rv.status === 0) {
    const same = psnrRgb(PNG.sync.read(readFileSync(view0)), reference);
    log(`cameras.json view 0 (catgs-render) vs the fixed pose's render: ${same.toFixed(2)} dB`);
    check(same >= 40, 'view 0 of the exported cameras.json is the pose the page sent (>= 40 dB against its render)');
  }
  if (loadgenBin && existsSync(loadgenBin)) {
    const jsonOut = path.join(outDir, 'recorded_loadgen.json');
    const lg = spawnSync(loadgenBin, ['--port', String(port), '--scene', scene, '--trace', `cameras:${camerasPath}`, '--size', '160x120',
      '--seconds', '2', '--rate', '10', '--check-every', '2', '--warmup', '1', '--progress', '0', '--json', jsonOut], { encoding: 'utf8' });
    log(`catgs-loadgen on the recorded path:\n${lg.stdout.replace(/^/gm, '    ')}`);
    check(lg.status === 0, `catgs-loadgen replays the recorded cameras.json (exit ${lg.status}${lg.stderr ? `: ${lg.stderr.trim()}` : ''})`);
    if (lg.status === 0) {
      const r = JSON.parse(readFileSync(jsonOut, 'utf8')).run.sessions[0];
      check(r.frames > 5 && r.checked > 0 && r.check_failures === 0, `... its frames match the CPU reference (${r.frames} frames, ${r.checked} checked, min ${r.psnr_min_db} dB)`);
    }
  } else {
    log('catgs-loadgen not given: the replay of the recorded path is not checked');
  }
  const lastSent = [p0[0] + 0.048 * scale, p0[1], p0[2] + 0.048 * scale]; // the loop's k = 12 above
  await checkTraceExport(page, { port, reference, render, lastSent });
  await page.close();

  // ---- A server with a token and one session: the token prompt, then the full-server retry,
  // then streaming once the first viewer leaves, with nothing stale on screen.
  const guarded = await startServer(['--token', 's3cret', '--max-sessions', '1', '--full-retry-ms', '1500']);
  const holder = await context.newPage();
  await holder.goto(`${guarded.base}/?token=s3cret`);
  await holder.waitForFunction(() => window.catgs && window.catgs.connected, null, { timeout: 30000 });
  const visitor = await context.newPage();
  visitor.on('console', (m) => pageLog.push(`visitor console.${m.type()}: ${m.text()}`));
  await visitor.goto(`${guarded.base}/`);
  const msg = () => visitor.evaluate(() => document.getElementById('messages').textContent);
  const seen = (what, re) => waitFor(what, async () => re.test(await msg()), 15000).then(() => true, () => false);
  check(await seen('the token prompt', /needs an access token/) && await visitor.isVisible('#token-input'), 'no token: the page asks for one');
  await visitor.fill('#token-input', 's3cret');
  await visitor.press('#token-input', 'Enter');
  check(await seen('"server full"', /server full, retrying in \d s/), 'the right token on a full server: "server full, retrying in N s"');
  await visitor.screenshot({ path: path.join(outDir, 'server_full.png') });
  await holder.close();
  await waitFor('the visitor to stream', () => visitor.evaluate(() => window.catgs.framesDecoded > 0), 30000);
  await sleep(500);
  const after = await visitor.evaluate(() => window.catgs.overlayText());
  check(after === '', `once in, nothing stale on screen (${JSON.stringify(after)})`);
  await visitor.screenshot({ path: path.join(outDir, 'visitor_streaming.png') });
  await visitor.close();

  await checkAdaptiveQuality();
  await checkScenePicker();
  await checkServerStop();
}

// A server stopped with Ctrl-C (SIGINT) and started again on its port (issue 75): the page says
// "server stopping" until it streams again, never "disconnected" (a stop is not a network fault),
// is connected again within 3.5 s of the server answering HTTP and then streams. The page retries
// every second; an attempt that lands while the scene still loads is told "server starting ...
// retry after 300 ms" (before issue 91 2000 ms: seen connected after 2177 ms so), and the page
// says the server is starting, never "server full". The bound stays 1 s + 2 s + margin. (The first
// frame's time after that is the machine's load, not the retry: a clean-clone run at bd5e2a6
// beside an 18 GB benchmark took 2.8 s to it, so it is not bounded.)
async function checkServerStop() {
  const first = await startServer();
  const page = await context.newPage();
  page.on('console', (m) => pageLog.push(`stop console.${m.type()}: ${m.text()}`));
  await page.goto(`${first.base}/`);
  await page.waitForFunction(() => window.catgs && window.catgs.framesDecoded > 0, null, { timeout: 30000 });
  const msg = () => page.evaluate(() => document.getElementById('messages').textContent);
  const exited = new Promise((r) => first.proc.once('exit', r));
  first.proc.kill('SIGINT');
  await exited;
  const said = new Set();
  for (const t0 = Date.now(); Date.now() - t0 < 5000; await sleep(150)) said.add(await msg());
  const words = [...said].join(' | ');
  check([...said].some((w) => /server stopping/.test(w)), `after Ctrl-C the page says "server stopping" (${words})`);
  check(![...said].some((w) => /disconnected|cannot reach/.test(w)), `...and not "disconnected" while the server is away (${words})`);
  const again = await startServer([], first.port);
  const back = Date.now();
  const before = await page.evaluate(() => window.catgs.framesDecoded);
  const saidBack = new Set(); // what the page says while the server starts again
  const connected = await waitFor('the page to connect again', async () => {
    saidBack.add(await msg());
    return page.evaluate(() => window.catgs.connected);
  }, 15000, 50).then(() => true, () => false);
  const tookConnect = Date.now() - back;
  const wordsBack = [...saidBack].join(' | ');
  check(![...saidBack].some((w) => /server full/.test(w)), `a starting server is not called full (${wordsBack})`);
  const streamed = await waitFor('the page to stream again', async () => (await page.evaluate(() => window.catgs.framesDecoded)) > before, 15000)
    .then(() => true, () => false);
  const took = Date.now() - back;
  check(connected && tookConnect <= 3500, `the page is connected again ${tookConnect} ms after the server's return (<= 3500 ms)`);
  check(streamed, `...and streams again (${took} ms after the server's return)`);
  await page.screenshot({ path: path.join(outDir, 'server_back.png') });
  await page.close();
}

// Runs a C++ tool; returns spawnSync's result with a one-line summary of why it failed.
function runTool(bin, toolArgs) {
  const r = spawnSync(bin, toolArgs, { encoding: 'utf8' });
  r.why = `exit ${r.status}${r.status === 0 ? '' : `: ${(r.stderr || '').trim().split('\n').slice(-2).join(' / ')}`}`;
  return r;
}

const pngsIn = (dir) => (existsSync(dir) ? readdirSync(dir).filter((n) => /^frame_\d+\.png$/.test(n)).sort() : []);
const readPng = (file) => PNG.sync.read(readFileSync(file));

// The same recording exported as our trace file (paths.js toTraceFile) is read by the C++ side
// (render_core/camera/trace.cpp read_trace): catgs-render renders one image per pose line, its
// first and last poses are the poses the page sent, and catgs-loadgen replays it with its
// reference check. `ctx`: the server's port, the fixed pose's reference image (decoded), the
// test's own render(name, position) and the last position the recording was sent.
async function checkTraceExport(page, ctx) {
  const traceText = await page.evaluate(() => window.catgs.exportTrace());
  const tracePath = path.join(outDir, 'recorded.trace');
  writeFileSync(tracePath, traceText || '');
  // Pose lines: neither blank, nor a comment, nor the 'catgs-trace 1' header.
  const poses = (traceText || '').split('\n').filter((l) => l.trim() && !l.startsWith('#')).length - 1;
  const recorded = (await page.evaluate(() => window.catgs.recording) || []).length;
  check(poses >= 3 && poses === recorded, `the recording exports as a trace of ${poses} poses (${recorded} recorded)`);
  if (poses < 2) return;

  // Every pose line is read: one image each (small, so that all of them render quickly).
  const allDir = path.join(outDir, 'recorded_trace_all');
  rmSync(allDir, { recursive: true, force: true });
  const all = runTool(renderBin, ['--scene', scene, '--trace', tracePath, '--out-dir', allDir, '--width', '96', '--height', '72', '--renderer', 'cpu']);
  const written = pngsIn(allDir).length;
  check(all.status === 0 && written === poses, `catgs-render reads the page's trace: ${written} images for its ${poses} poses (${all.why})`);

  // Its first and last poses at full size (--every: just those two) against renders of the poses
  // the test sent; the last one must not match the first (the path moved).
  const endsDir = path.join(outDir, 'recorded_trace_ends');
  rmSync(endsDir, { recursive: true, force: true });
  const ends = runTool(renderBin, ['--scene', scene, '--trace', tracePath, '--out-dir', endsDir, '--every', String(poses - 1), '--renderer', 'cpu']);
  const [firstPng, lastPng] = pngsIn(endsDir).map((n) => path.join(endsDir, n));
  check(ends.status === 0 && !!lastPng, `catgs-render renders the trace's first and last poses (${ends.why})`);
  if (lastPng) {
    const lastRef = readPng(ctx.render('recorded_last', ctx.lastSent));
    const first = psnrRgb(readPng(firstPng), ctx.reference);
    const last = psnrRgb(readPng(lastPng), lastRef);
    const lastVsStart = psnrRgb(readPng(lastPng), ctx.reference);
    log(`trace pose 0 vs the fixed pose's render ${first.toFixed(2)} dB; last pose vs its render ${last.toFixed(2)} dB, vs the start ${lastVsStart.toFixed(2)} dB`);
    check(first >= 40, 'the trace\'s first pose is the pose the page sent first (>= 40 dB against its render)');
    check(last >= 40 && last > lastVsStart + 3, 'the trace\'s last pose is the pose the page sent last (>= 40 dB, and not the start view)');
  }

  if (!loadgenBin || !existsSync(loadgenBin)) return;
  const jsonOut = path.join(outDir, 'recorded_trace_loadgen.json');
  const lg = runTool(loadgenBin, ['--port', String(ctx.port), '--scene', scene, '--trace', tracePath, '--size', '160x120',
    '--seconds', '2', '--rate', '10', '--check-every', '2', '--warmup', '1', '--progress', '0', '--json', jsonOut]);
  log(`catgs-loadgen on the recorded trace:\n${lg.stdout.replace(/^/gm, '    ')}`);
  check(lg.status === 0, `catgs-loadgen replays the page's trace file (${lg.why})`);
  if (lg.status !== 0) return;
  const r = JSON.parse(readFileSync(jsonOut, 'utf8')).run.sessions[0];
  check(r.frames > 5 && r.checked > 0 && r.check_failures === 0,
    `... its frames match the CPU reference (${r.frames} frames, ${r.checked} checked, min ${r.psnr_min_db} dB)`);
}

// One counter from the server's /metrics (Prometheus text); NaN when it is missing.
async function metric(base, name) {
  const text = await (await fetch(`${base}/metrics`)).text();
  const m = new RegExp(`^${name} (\\S+)$`, 'm').exec(text);
  return m ? Number(m[1]) : NaN;
}

// In the page: a timer moves the camera every 5 ms (about 200 poses a second, far more than the
// CPU renderer draws at this size, so the server replaces most of them) and notes the narrowest
// frame the page showed. window.catgsFlood.stop() ends it and returns the last pose's sequence.
function startPoseFlood(page) {
  return page.evaluate(() => {
    const { position: p, orientation: q, fovDeg: f } = window.catgs.pose();
    const flood = (window.catgsFlood = { minWidth: Infinity, sent: 0 });
    let i = 0;
    const timer = setInterval(() => {
      const d = 0.02 * Math.sin(++i * 0.05);
      if (window.catgs.setPose([p[0] + d, p[1], p[2] + d], q, f) !== null) flood.sent++;
      const shown = window.catgs.lastFrame;
      if (shown) flood.minWidth = Math.min(flood.minWidth, shown.width);
    }, 5);
    flood.stop = () => {
      clearInterval(timer);
      return window.catgs.lastPoseSent.sequence;
    };
  });
}

// In the page: a timer sends one pose every `intervalMs`, moving the camera a little, and notes
// the first frame shown for each of these poses (pose sequence, size, time): the answer, not a
// refine frame of the same pose that may follow. window.catgsSlow.stop() ends it and returns
// what it noted.
function startSlowPoses(page, intervalMs) {
  return page.evaluate((ms) => {
    const { position: p, orientation: q, fovDeg: f } = window.catgs.pose();
    const slow = (window.catgsSlow = { first: null, sent: 0, answers: [] });
    let i = 0;
    let answered = -1;
    const send = () => {
      const s = window.catgs.setPose([p[0] + 0.01 * Math.sin(++i * 0.5), p[1], p[2]], q, f);
      if (s === null) return;
      slow.sent++;
      if (slow.first === null) slow.first = s;
    };
    const watch = setInterval(() => {
      const fr = window.catgs.lastFrame;
      if (!fr || slow.first === null || fr.poseSequence < slow.first || fr.poseSequence <= answered) return;
      answered = fr.poseSequence;
      slow.answers.push({ pose: fr.poseSequence, width: fr.width, height: fr.height, at: performance.now() });
    }, 10);
    send();
    const timer = setInterval(send, ms);
    slow.stop = () => {
      clearInterval(timer);
      clearInterval(watch);
      return { sent: slow.sent, answers: slow.answers };
    };
  }, intervalMs);
}

// Adaptive quality (server --adaptive-quality on, rule in server/session/adaptive_quality.h) as
// the page shows it: under a pose flood the frames it draws get narrower and /metrics counts the
// step down; once the camera stops, a full-size refine frame of the last pose is shown; then
// slow poses (the frames fit again) bring the level back up: /metrics counts as many steps up as
// there were down, and the page shows those poses at full size again.
async function checkAdaptiveQuality() {
  const t0 = Date.now();
  const aq = await startServer(['--adaptive-quality', 'on']);
  const page = await context.newPage();
  page.on('console', (m) => pageLog.push(`adaptive console.${m.type()}: ${m.text()}`));
  await page.goto(`${aq.base}/`);
  await page.waitForFunction(() => window.catgs && window.catgs.connected, null, { timeout: 30000 });
  const full = await page.evaluate(() => window.catgs.viewport);
  const downBefore = await metric(aq.base, 'catgs_quality_down_total');
  check(downBefore === 0, `adaptive: /metrics has catgs_quality_down_total, 0 before any motion (${downBefore})`);

  await startPoseFlood(page);
  const narrowest = () => page.evaluate(() => window.catgsFlood.minWidth);
  const narrowed = await waitFor('a frame narrower than the viewport', async () => (await narrowest()) < full.width, 20000)
    .then(() => true, () => false);
  const minWidth = await narrowest();
  check(narrowed && minWidth <= 0.75 * full.width,
    `adaptive: under a pose flood the page shows narrower frames (${minWidth} wide, viewport ${full.width})`);
  const downAfter = await waitFor('catgs_quality_down_total to rise', async () => {
    const v = await metric(aq.base, 'catgs_quality_down_total');
    return v > downBefore ? v : 0;
  }, 10000).catch(() => downBefore);
  check(downAfter > downBefore, `adaptive: /metrics catgs_quality_down_total rose (${downBefore} -> ${downAfter})`);
  // Each pose carries a receipt for the newest frame the page received (Pose.received_ms): the
  // server's rate controller matched them to frames it sent (protobufjs's field names and all).
  // (At least one: a busy CI machine renders only a few frames of the flood.)
  const receipts = await waitFor('catgs_frame_receipts_total to count a receipt', async () => {
    const v = await metric(aq.base, 'catgs_frame_receipts_total');
    return v >= 1 ? v : 0;
  }, 10000).catch(() => 0);
  check(receipts >= 1, `the page's poses carry frame receipts the server matched (catgs_frame_receipts_total ${receipts})`);

  // The camera stops: a refine frame of the last pose, at the viewport's size, follows.
  const last = await page.evaluate(() => window.catgsFlood.stop());
  const sent = await page.evaluate(() => window.catgsFlood.sent);
  const refined = await waitFor(`a ${full.width}x${full.height} frame of pose ${last}`, () => page.evaluate(([s, w, h]) => {
    const f = window.catgs.lastFrame;
    return f && f.poseSequence === s && f.width === w && f.height === h;
  }, [last, full.width, full.height]), 10000).then(() => true, () => false);
  const shown = await page.evaluate(() => window.catgs.lastFrame);
  check(refined, `adaptive: once the camera stops, the last pose is shown at full size (shown: pose ${shown.poseSequence}, ` +
    `${shown.width}x${shown.height}; last sent ${last})`);
  const refines = await metric(aq.base, 'catgs_refine_frames_total');
  check(refines >= 1, `adaptive: /metrics counts the refine frame (catgs_refine_frames_total ${refines})`);
  await page.screenshot({ path: path.join(outDir, 'adaptive_refined.png') });

  // Slow poses: the rule climbs one level once the session has been 3 s at a level, the camera
  // moved in the last second with no pose skipped, and the frame cost at this level, scaled by
  // the pixels of the level above (x1.78, x2.25), is under 0.6 of the average pose interval
  // (which starts from the flood's few ms: gaps of 1 s or more are not counted). On the CPU
  // renderer the biker costs about the same at every level (its Gaussians, not its pixels:
  // 160-270 ms a frame on 2 cores busy with other builds), so one pose every 400 ms (budget
  // 240 ms) climbed back on a quiet machine but not within 20 s on a busy one; one every 900 ms
  // (budget 540 ms) does on both. The server's refine frames follow each reduced answer (the
  // camera is still for 500 ms); they are left out. The first slow pose is still answered at the
  // reduced size (a refine is not a level change); once the level is back, they are full size.
  const tSlow = Date.now();
  const downs = await metric(aq.base, 'catgs_quality_down_total');
  const upBefore = await metric(aq.base, 'catgs_quality_up_total');
  check(upBefore === 0, `adaptive: /metrics has catgs_quality_up_total, 0 before the slow poses (${upBefore})`);
  await startSlowPoses(page, 900);
  const upAfter = await waitFor(`catgs_quality_up_total to reach ${downs}`, async () => {
    const v = await metric(aq.base, 'catgs_quality_up_total');
    return v >= downs ? v : 0;
  }, 20000).catch(() => metric(aq.base, 'catgs_quality_up_total'));
  const upS = (Date.now() - tSlow) / 1000;
  check(upAfter > upBefore && upAfter >= downs,
    `adaptive: under slow poses /metrics catgs_quality_up_total rose back (${upBefore} -> ${upAfter}, ${downs} down) within ${upS.toFixed(1)} s`);
  // A slow pose sent after that is answered at the viewport's size.
  const mark = await page.evaluate(() => window.catgs.lastPoseSent.sequence);
  const restored = await waitFor('a slow pose shown at full size', () => page.evaluate(([m, w, h]) =>
    window.catgsSlow.answers.find((a) => a.pose > m && a.width === w && a.height === h) || null, [mark, full.width, full.height]), 5000)
    .catch(() => null);
  const slow = await page.evaluate(() => window.catgsSlow.stop());
  // The sizes the slow poses were answered at, in order, run-length coded: "240x180 x4, 360x270 x3".
  const runs = [];
  for (const a of slow.answers) {
    const size = `${a.width}x${a.height}`;
    if (runs.length && runs.at(-1).size === size) runs.at(-1).n++;
    else runs.push({ size, n: 1 });
  }
  log(`adaptive: ${slow.sent} slow poses in ${((Date.now() - tSlow) / 1000).toFixed(1)} s, answered at: ` +
    `${runs.map((r) => `${r.size} x${r.n}`).join(', ') || 'none'}`);
  const firstSlow = slow.answers[0];
  check(!!firstSlow && firstSlow.width < full.width,
    `adaptive: the first slow pose is still shown at the reduced size (${firstSlow ? `${firstSlow.width}x${firstSlow.height}` : 'none shown'})`);
  check(!!restored, `adaptive: then slow poses are shown at full size again (${restored ? `pose ${restored.pose}, ` +
    `${restored.width}x${restored.height}` : `none after pose ${mark} within 5 s`}; catgs_refine_frames_total ` +
    `${await metric(aq.base, 'catgs_refine_frames_total')})`);
  await page.close();
  log(`adaptive quality scenario: ${sent} poses flooded, ${((Date.now() - t0) / 1000).toFixed(1)} s ` +
    `(slow poses until full size: ${((Date.now() - tSlow) / 1000).toFixed(1)} s)`);
}

// Opens `page` on a key frame of its current pose (KeyFrameRequest re-sends the pose); returns
// that frame's metadata and the decoded canvas.
async function keyFrameShot(page, timeout = 60000) {
  const seq = await page.evaluate(() => window.catgs.requestKeyFrame());
  await page.waitForFunction((s) => {
    const f = window.catgs.lastFrame;
    return f && f.poseSequence >= s && f.keyFrame;
  }, seq, { timeout });
  const shot = await page.evaluate(() => ({ frame: window.catgs.lastFrame, png: window.catgs.snapshot() }));
  return { seq, frame: shot.frame, png: PNG.sync.read(Buffer.from(shot.png.split(',')[1], 'base64')) };
}

// The scene picker against a real server with two scenes (--scene twice: the bundled biker, then
// flowers_sh3 from the data folder, loaded on first use): the picker lists GET /scenes' names,
// the first chosen; choosing the second reopens the page with ?scene=flowers_sh3, whose Welcome
// names it and whose frame at the scene's start pose matches catgs-render of flowers_sh3 at that
// pose (>= minPsnr) and not catgs-render of biker at the same pose.
async function checkScenePicker() {
  const second = path.join(dataDir, 'scenes/flowers_sh3.ply');
  if (!existsSync(second)) {
    log(`SKIP (scene picker on a real server): ${second} is missing (give the data folder with --data or CATGS_DATA_DIR)`);
    return;
  }
  const t0 = Date.now();
  const two = await startServer(['--scene', second]);
  // /scenes is [] until the first scene has loaded, and the page asks once, when it opens (a page
  // opened during the server's start-up shows no picker): wait for the list first.
  const listed = async () => {
    const r = await fetch(`${two.base}/scenes`);
    const list = r.ok ? await r.json() : [];
    return Array.isArray(list) && list.length ? list.map((s) => String(s.name)) : null;
  };
  const names = (await waitFor('GET /scenes to list the scenes', listed, 60000, 200).catch(() => null)) || [];
  check(names.join(',') === 'biker,flowers_sh3', `scenes: GET /scenes lists biker, then flowers_sh3 (${names.join(', ')})`);
  const page = await context.newPage();
  page.on('console', (m) => pageLog.push(`scenes console.${m.type()}: ${m.text()}`));
  await page.goto(`${two.base}/`);
  await page.waitForFunction(() => window.catgs && window.catgs.connected, null, { timeout: 30000 });
  const picker = await waitFor('the scene picker', () => page.evaluate(() => {
    const p = document.getElementById('scene-picker');
    return p && !p.hidden && p.options.length ? { names: [...p.options].map((o) => o.value), value: p.value } : null;
  }), 10000).catch(() => null);
  check(!!picker && picker.names.join(',') === names.join(',') && picker.value === names[0],
    `scenes: the picker lists /scenes' names, the first chosen (${JSON.stringify(picker)})`);
  if (!picker || !picker.names.includes('flowers_sh3')) return;

  await Promise.all([page.waitForNavigation({ timeout: 30000 }), page.selectOption('#scene-picker', 'flowers_sh3')]);
  check(new URL(page.url()).searchParams.get('scene') === 'flowers_sh3', `scenes: the page reopened with ?scene=flowers_sh3 (${page.url()})`);
  // The scene loads on first use: the Welcome follows once it is there.
  await page.waitForFunction(() => window.catgs && window.catgs.connected && window.catgs.welcome, null, { timeout: 120000 });
  const welcome = await page.evaluate(() => window.catgs.welcome);
  check(welcome.scene_name === 'flowers_sh3', `scenes: the new session's Welcome names flowers_sh3 (${welcome.scene_name})`);
  const chosen = await page.evaluate(() => document.getElementById('scene-picker').value);
  check(chosen === 'flowers_sh3', `scenes: the picker shows flowers_sh3 chosen (${chosen})`);

  // The scene's start pose, sent by the hook, then a key frame of it.
  const ip = welcome.initial_pose;
  const pose = {
    position: [ip.position.x, ip.position.y, ip.position.z],
    orientation: [ip.orientation.w, ip.orientation.x, ip.orientation.y, ip.orientation.z],
    fovDeg: ip.vertical_fov_deg,
  };
  await page.evaluate((p) => window.catgs.setPose(p.position, p.orientation, p.fovDeg), pose);
  const shot = await keyFrameShot(page);
  const { width, height } = shot.frame;
  writeFileSync(path.join(outDir, 'scene_flowers_streamed.png'), PNG.sync.write(shot.png));
  await page.screenshot({ path: path.join(outDir, 'scene_picker_flowers.png') });
  const own = psnrRgb(shot.png, readPng(renderPose(second, 'scene_flowers_reference', pose, width, height)));
  const other = psnrRgb(shot.png, readPng(renderPose(scene, 'scene_biker_same_pose', pose, width, height)));
  log(`scenes: flowers_sh3 frame (pose ${shot.frame.poseSequence}, ${width}x${height}) vs catgs-render of flowers_sh3 ` +
    `${own.toFixed(2)} dB, vs biker at the same pose ${other.toFixed(2)} dB`);
  check(own >= minPsnr, `scenes: the frame shown after the switch matches flowers_sh3's render of its pose (${own.toFixed(2)} dB >= ${minPsnr} dB)`);
  check(other < minPsnr && other < own - 3, `scenes: ... and not biker's render of the same pose (${other.toFixed(2)} dB)`);
  await page.close();
  log(`scene picker scenario: ${((Date.now() - t0) / 1000).toFixed(1)} s`);
}

let code = 0;
try {
  await run();
  if (failures.length) code = 1;
} catch (e) {
  console.error(`[e2e] FAIL: ${e.stack || e}`);
  code = 1;
} finally {
  if (context) await context.close().catch(() => {});
  await stopServers(servers);
  rmSync(profileDir, { recursive: true, force: true });
}
if (code !== 0) {
  console.error('[e2e] page log:\n' + pageLog.slice(-60).join('\n'));
  console.error('[e2e] server log (tail):\n' + serverLog.slice(-4000));
}
console.log(code === 0 ? '1 passed, 0 failed' : '0 passed, 1 failed');
process.exit(code);
