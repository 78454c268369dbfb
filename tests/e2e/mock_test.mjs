// Browser test of the page's own behaviour against mock_server.mjs (no catgs-server needed):
// handshake and Hello fields, pose flow, WebCodecs decoding, overlay, the JSON schema fallback,
// server Error display + reconnect message + reconnect, decoder error recovery, Resize.
// usage: node mock_test.mjs     Exit codes: 0 pass, 1 fail, 77 skipped (reason printed).
import { existsSync, mkdtempSync, rmSync } from 'node:fs';
import { createRequire } from 'node:module';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, '../..');
const CHROMIUM = process.env.CATGS_CHROMIUM || '/usr/bin/chromium';
if (!existsSync(CHROMIUM)) {
  console.log(`SKIP: ${CHROMIUM} is missing (apt-get install chromium)`);
  process.exit(77);
}
if (!existsSync(path.join(here, 'node_modules/playwright-core'))) {
  console.log('SKIP: tests/e2e/node_modules is missing: run scripts/setup_web.sh');
  process.exit(77);
}
const require = createRequire(import.meta.url);
const { chromium } = require('playwright-core');
const { startMockServer } = await import('./mock_server.mjs');

const log = (...m) => console.log('[mock]', ...m);
const failures = [];
const check = (ok, what) => {
  log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
  if (!ok) failures.push(what);
};

const mock = await startMockServer({ webRoot: path.join(repo, 'web_client'), protoFile: path.join(repo, 'proto/catgs_stream.proto') });
const base = `http://127.0.0.1:${mock.port}`;
const profile = mkdtempSync(path.join(os.tmpdir(), 'catgs-mock-chromium-'));
let context = null;
const pageLog = [];

// Keeps the camera moving through the hook (each setPose sends a Pose) until fn() holds.
async function moveUntil(page, fn, arg, timeoutMs = 15000) {
  const end = Date.now() + timeoutMs;
  for (let i = 1; Date.now() < end; i++) {
    const done = await page.evaluate(([i, src, a]) => {
      const c = window.catgs;
      if (c.connected) c.setPose([0.001 * i, 0, -4], [1, 0, 0, 0], 50);
      return new Function('c', 'a', `return (${src})(c, a);`)(c, a); // eslint-disable-line no-new-func
    }, [i, fn.toString(), arg]);
    if (done) return true;
    await page.waitForTimeout(50);
  }
  return false;
}

async function openPage(url) {
  const page = await context.newPage();
  page.on('console', (m) => pageLog.push(`${url} console.${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => pageLog.push(`${url} pageerror: ${e.message}`));
  await page.goto(url);
  return page;
}

try {
  context = await chromium.launchPersistentContext(profile, {
    executablePath: CHROMIUM,
    headless: true,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
    viewport: { width: 160, height: 120 },
    deviceScaleFactor: 1,
  });

  // 1. Normal session.
  {
    const page = await openPage(`${base}/`);
    check(await moveUntil(page, (c) => c.framesDecoded >= 10), 'normal: 10 frames decoded');
    const hello = mock.received.find((r) => r.body === 'hello');
    check(!!hello && hello.msg.protocol_version === 1 && hello.msg.viewport_width === 160 && hello.msg.viewport_height === 120 &&
      JSON.stringify(hello.msg.codecs) === '[1]', `normal: Hello ${JSON.stringify(hello && hello.msg)}`);
    const poses = mock.received.filter((r) => r.session === hello.session && r.body === 'pose').map((r) => r.msg);
    check(poses.length >= 10 && poses.every((p, i) => p.sequence === i + 1), 'normal: pose sequences count 1, 2, 3, ...');
    check(poses.every((p, i) => i === 0 || p.client_time_ms >= poses[i - 1].client_time_ms), 'normal: client_time_ms is monotonic');
    check(poses[0].vertical_fov_deg === 50 && poses[0].orientation.w === 1, 'normal: first pose is the Welcome initial pose');
    const s = await page.evaluate(() => ({ lf: window.catgs.lastFrame, text: window.catgs.overlayText(), errs: window.catgs.decoderErrors }));
    check(s.lf.width === 160 && s.lf.height === 120, 'normal: frame size 160x120');
    check(/FPS (\d*[1-9]\d*(\.\d)?|0\.[1-9])/.test(s.text) && /latency \d+ ms/.test(s.text) && s.text.includes('renderer cpu (exact)') &&
      s.text.includes('encoder x264') && s.text.includes('avc1.42'), `normal: overlay ${JSON.stringify(s.text)}`);
    check(s.errs === 0, 'normal: no decoder errors');

    // Input: a mouse drag orbits (orientation changes, distance to the target is kept), the wheel
    // zooms, a held W flies forward; each goes out as Poses through the animation-frame loop.
    const before = await page.evaluate(() => window.catgs.lastPoseSent);
    await page.mouse.move(80, 60);
    await page.mouse.down();
    await page.mouse.move(110, 70, { steps: 5 });
    await page.mouse.up();
    await page.waitForTimeout(200);
    const afterDrag = await page.evaluate(() => window.catgs.lastPoseSent);
    // The target sits 4 units ahead of the last setPose camera: (x, 0, 0) with x tiny.
    const target = [before.position[0], 0, 0];
    const dist = (p) => Math.hypot(p[0] - target[0], p[1] - target[1], p[2] - target[2]);
    check(afterDrag.sequence > before.sequence && afterDrag.orientation[0] < 0.9999 &&
      Math.abs(dist(afterDrag.position) - dist(before.position)) < 1e-6,
    `input: drag orbits around the target (pose ${before.sequence} -> ${afterDrag.sequence})`);
    await page.mouse.wheel(0, -200);
    await page.waitForTimeout(200);
    const afterWheel = await page.evaluate(() => window.catgs.lastPoseSent);
    check(dist(afterWheel.position) < dist(afterDrag.position), 'input: wheel up zooms in');
    await page.keyboard.down('KeyW');
    await page.waitForTimeout(300);
    await page.keyboard.up('KeyW');
    await page.waitForTimeout(100);
    const afterFly = await page.evaluate(() => window.catgs.lastPoseSent);
    check(afterFly.sequence > afterWheel.sequence + 2 && dist(afterFly.position) < dist(afterWheel.position), 'input: W flies forward, a pose per frame');

    // Resize: the page sends Resize with the new size in device pixels (even).
    await page.setViewportSize({ width: 201, height: 151 });
    const gotResize = await moveUntil(page, () => true, null, 100) &&
      (await new Promise((r) => setTimeout(r, 600)), mock.received.some((m) => m.body === 'resize'));
    const rz = mock.received.find((m) => m.body === 'resize');
    check(gotResize && rz.msg.viewport_width === 200 && rz.msg.viewport_height === 150, `resize: ${JSON.stringify(rz && rz.msg)}`);
    await page.close();
  }

  // 2. The server will not serve .proto: the page falls back to the JSON descriptor.
  {
    const page = await openPage(`${base}/noproto/`);
    check(await moveUntil(page, (c) => c.framesDecoded >= 3), 'noproto: streams with the JSON schema');
    await page.close();
  }

  // 3. Server Error: shown with code and reason, then "reconnecting in N s", then a new session.
  {
    const page = await openPage(`${base}/?ws=ws://127.0.0.1:${mock.port}/ws-error`);
    const sawError = await moveUntil(page, (c) => /server error ERROR_TOO_SLOW \(8\): mock: too slow/.test(c.overlayText()));
    check(sawError, 'error: overlay shows the server error code and reason');
    const text = await page.evaluate(() => window.catgs.overlayText());
    check(/disconnected, reconnecting (in \d+ s|now)/.test(text), `error: overlay shows the reconnect countdown (${JSON.stringify(text)})`);
    const helloCount = () => mock.received.filter((r) => r.path === '/ws-error' && r.body === 'hello').length;
    check(await moveUntil(page, (c, n) => c.connected && n >= 0, 0, 8000) && helloCount() >= 2, 'error: reconnected with a new Hello');
    await page.close();
  }

  // 4. An undecodable key frame: decoder error, KeyFrameRequest, and decoding resumes.
  {
    const page = await openPage(`${base}/?ws=ws://127.0.0.1:${mock.port}/ws-garbage`);
    check(await moveUntil(page, (c) => c.decoderErrors >= 1 && c.framesDecoded >= 10), 'garbage: decoder error seen and decoding goes on (10 frames)');
    check(mock.received.some((r) => r.path === '/ws-garbage' && r.body === 'key_frame_request'), 'garbage: the page asked for a key frame');
    await page.close();
  }
} catch (e) {
  failures.push(String(e.stack || e));
  console.error(e);
} finally {
  if (context) await context.close().catch(() => {});
  await mock.close();
  rmSync(profile, { recursive: true, force: true });
}
if (failures.length) console.error('[mock] page log:\n' + pageLog.slice(-40).join('\n'));
console.log(failures.length ? '0 passed, 1 failed' : '1 passed, 0 failed');
process.exit(failures.length ? 1 : 0);
