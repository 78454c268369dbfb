// Browser test of the page's own behaviour against mock_server.mjs (no catgs-server needed):
// handshake and Hello fields, pose flow, WebCodecs decoding, overlay, the JSON schema fallback,
// server Error display + reconnect message + reconnect, decoder error recovery, Resize; the
// viewer's states (first view, unreachable, wrong token, server full, stopping or restarting, a
// scene the server lacks), stale stats, reset, shared view links, the zoom-out bound, help,
// fullscreen, camera paths and tours, latency hiding (the held frame re-projected, its uncovered
// part filled from its edge), the scene picker, Esc and the Notes panel, panels clear of the
// stats, and a phone at DPR 3 (one row of 40 px toolbar buttons, More).
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
const { PNG } = require('pngjs');

const log = (...m) => console.log('[mock]', ...m);
const shotsDir = process.env.CATGS_MOCK_SHOTS || '';
const shot = async (page, name) => {
  if (shotsDir) await page.screenshot({ path: path.join(shotsDir, `${name}.png`) });
};
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
// The page's words: the state messages in the middle and the short notices at the bottom.
const messageText = (page) => page.evaluate(() => ['messages', 'notice'].map((id) => document.getElementById(id)?.textContent || '').filter(Boolean).join('\n'));
async function waitText(page, re, timeoutMs = 8000) {
  const end = Date.now() + timeoutMs;
  while (Date.now() < end) {
    if (re.test(await messageText(page))) return true;
    await sleep(100);
  }
  return false;
}
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

async function waitFor(fn, timeoutMs) {
  const end = Date.now() + timeoutMs;
  while (Date.now() < end && !fn()) await sleep(50);
  return fn();
}

async function openPage(url, ctx = context) {
  const page = await ctx.newPage();
  page.on('console', (m) => pageLog.push(`${url} console.${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => pageLog.push(`${url} pageerror: ${e.message}`));
  await page.goto(url);
  return page;
}

// Headless Debian Chromium (the flags of harness.mjs) with a profile in `dir` and `options` on top.
const launch = (dir, options) => chromium.launchPersistentContext(dir, {
  executablePath: CHROMIUM,
  headless: true,
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
    '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  ...options,
});

try {
  context = await launch(profile, { viewport: { width: 320, height: 240 }, deviceScaleFactor: 1 });

  // 1. Normal session.
  {
    const page = await openPage(`${base}/?stats=1`);
    check(await moveUntil(page, (c) => c.framesDecoded >= 10), 'normal: 10 frames decoded');
    const hello = mock.received.find((r) => r.body === 'hello');
    check(!!hello && hello.msg.protocol_version === 1 && hello.msg.viewport_width === 320 && hello.msg.viewport_height === 240 &&
      JSON.stringify(hello.msg.codecs) === '[2,1]', `normal: Hello (codecs AV1 then H.264: Debian's Chromium decodes both) ${JSON.stringify(hello && hello.msg)}`);
    const poses = mock.received.filter((r) => r.session === hello.session && r.body === 'pose').map((r) => r.msg);
    check(poses.length >= 10 && poses.every((p, i) => p.sequence === i + 1), 'normal: pose sequences count 1, 2, 3, ...');
    check(poses.every((p, i) => i === 0 || p.client_time_ms >= poses[i - 1].client_time_ms), 'normal: client_time_ms is monotonic');
    check(poses[0].vertical_fov_deg === 50 && poses[0].orientation.w === 1, 'normal: first pose is the Welcome initial pose');
    // Pose.shown_latency_ms: nothing before the first frame, then the newest frame's latency.
    const reported = poses.map((p) => p.shown_latency_ms || 0);
    check(reported[0] === 0 && reported.filter((v) => v > 0 && v < 5000).length >= poses.length / 2,
      `normal: poses report the shown frames' latency (${reported.slice(0, 6).map((v) => v.toFixed(0)).join(', ')}, ...)`);
    const s = await page.evaluate(() => ({ lf: window.catgs.lastFrame, text: window.catgs.overlayText(), errs: window.catgs.decoderErrors }));
    check(s.lf.width === 160 && s.lf.height === 120, 'normal: frame size 160x120');
    check(/FPS (\d*[1-9]\d*(\.\d)?|0\.[1-9])/.test(s.text) && /latency \d+ ms/.test(s.text) && s.text.includes('renderer cpu (exact)') &&
      s.text.includes('encoder x264') && s.text.includes('avc1.42'), `normal: overlay ${JSON.stringify(s.text)}`);
    check(await waitText(page, /^$/, 2000), 'normal: no state message while streaming');
    // The camera rests: the server's next Stats covers an interval without frames.
    await sleep(4200);
    const idle = await page.evaluate(() => window.catgs.overlayText());
    check(/server: idle/.test(idle) && !/render 0\.0 ms/.test(idle) && /FPS idle/.test(idle), `idle: no made-up numbers (${JSON.stringify(idle)})`);
    check(s.errs === 0, 'normal: no decoder errors');
    // The mock's Stats measured no link rate (link_kbps 0): while frames come, the stats say
    // nothing of a link, only the round trip and that nothing limits the stream (issue 64: "link"
    // only for a rate measured on a full link).
    await moveUntil(page, (c) => /not limited/.test(c.overlayText()));
    const moving = await page.evaluate(() => window.catgs.overlayText());
    check(/TCP rtt [\d.]+ ms {2}not limited/.test(moving) && !/\blink\b/.test(moving), `stats: no link rate unless measured (${JSON.stringify(moving)})`);
    // The encoder's picture and preset (Stats.encode_psnr_db_mean, .encoder); the connection's
    // round trip named as TCP's (the page's own is 'ping', when Pongs come).
    check(/picture 31\.5 dB \(x264 superfast\)/.test(moving) && !/ rtt/.test(moving.replace('TCP rtt', '')),
      `stats: the encoder's picture, the round trip named (${JSON.stringify(moving)})`);

    // Input: a mouse drag orbits (orientation changes, distance to the target is kept), the wheel
    // zooms, a held W flies forward; each goes out as Poses through the animation-frame loop.
    const before = await page.evaluate(() => window.catgs.lastPoseSent);
    await page.mouse.move(160, 120);
    await page.mouse.down();
    await page.mouse.move(190, 130, { steps: 5 });
    await page.mouse.up();
    await page.waitForTimeout(200);
    const afterDrag = await page.evaluate(() => window.catgs.lastPoseSent);
    // The target sits 5 units ahead of the last setPose camera, as far as the Welcome's orbit
    // centre from its initial pose (setPose keeps the distance): (x, 0, 1) with x tiny.
    const target = [before.position[0], 0, 1];
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
    // Zooming out stops at 1.5 scene scales from the orbit target (camera.js MAX_ORBIT_SCALES):
    // from the reset view (5 units from the orbit centre (0, 0, 1), scene_scale 5), 30 notches out
    // end 7.5 units away.
    await page.keyboard.press('r');
    await page.mouse.move(160, 120);
    for (let i = 0; i < 30; i++) await page.mouse.wheel(0, 100);
    await page.waitForTimeout(300);
    const far = await page.evaluate(() => window.catgs.lastPoseSent.position);
    check(Math.abs(Math.hypot(far[0], far[1], far[2] - 1) - 7.5) < 1e-6, `input: zoom out stops 1.5 scene scales from the orbit centre (${far.map((v) => v.toFixed(3))})`);

    // Resize: the page sends Resize with the new size in device pixels (even).
    await page.setViewportSize({ width: 401, height: 301 });
    const gotResize = await moveUntil(page, () => true, null, 100) &&
      (await new Promise((r) => setTimeout(r, 600)), mock.received.some((m) => m.body === 'resize'));
    const rz = mock.received.find((m) => m.body === 'resize');
    check(gotResize && rz.msg.viewport_width === 400 && rz.msg.viewport_height === 300, `resize: ${JSON.stringify(rz && rz.msg)}`);
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
    const page = await openPage(`${base}/?stats=1&ws=ws://127.0.0.1:${mock.port}/ws-error`);
    const sawError = await moveUntil(page, (c) => /too slow for the stream \(mock: too slow\); reconnecting (in \d+ s|now)/.test(c.overlayText()));
    check(sawError, 'error: the message says why in words, the reason and the reconnect countdown');
    const text = await page.evaluate(() => window.catgs.overlayText());
    check(!/ERROR_|CODEC_/.test(text), `error: no enum names (${JSON.stringify(text)})`);
    check(/not connected/.test(text) && !/FPS|server:|latency \d/.test(text), `error: no stale stats once disconnected (${JSON.stringify(text)})`);
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

  const wsUrl = (p) => `ws://127.0.0.1:${mock.port}${p}`;
  const hellos = (p) => mock.received.filter((r) => r.path === p && r.body === 'hello');
  const posesOf = (session) => mock.received.filter((r) => r.session === session && r.body === 'pose').map((r) => r.msg);

  // 5. Before the first frame: a readable state, the codec in words, no enum names.
  {
    const page = await openPage(`${base}/?stats=1&ws=${wsUrl('/ws-noframes')}`);
    check(await waitText(page, /rendering the first view/), 'first view: "rendering the first view" after Welcome');
    const t = await page.evaluate(() => window.catgs.overlayText());
    check(/H\.264/.test(t) && !/CODEC_/.test(t), `first view: codec shown as H.264, no enum name (${JSON.stringify(t)})`);
    await page.close();
  }

  // 6. A server that was never reached says so (not "disconnected"), with one error event (a host
  // page that listens to `error` alone learns it); retry now tries at once.
  {
    const page = await openPage(`${base}/?ws=ws://127.0.0.1:9/ws`);
    check(await waitText(page, /cannot reach the server, retrying (in \d+ s|now)/), 'unreachable: "cannot reach the server"');
    check(!/disconnected/.test(await messageText(page)), 'unreachable: not "disconnected"');
    await sleep(2500); // the retries that follow fail alike: no second event
    const errs = await page.evaluate(() => window.catgs.errors);
    check(errs.length === 1 && errs[0].name === 'UNREACHABLE' && errs[0].permanent === false,
      `unreachable: one error event UNREACHABLE (${JSON.stringify(errs)})`);
    await page.close();
  }

  // 7. Token: no retry loop; the page asks, a wrong token says so, the right one connects.
  {
    const page = await openPage(`${base}/?ws=${wsUrl('/ws-token')}`);
    check(await waitText(page, /this server needs an access token/), 'token: asks for a token');
    await sleep(3000);
    check(hellos('/ws-token').length === 1, `token: no retries after UNAUTHORIZED (${hellos('/ws-token').length} Hellos in 3 s)`);
    await page.fill('#token-input', 'wrong');
    await page.click('#messages button[type=submit]');
    check(await waitText(page, /wrong token/), 'token: a wrong token is named as such');
    await shot(page, 'token_prompt');
    await page.fill('#token-input', 'sesame');
    await page.keyboard.press('Enter');
    check(await moveUntil(page, (c) => c.framesDecoded >= 3), 'token: the right token streams');
    const h = hellos('/ws-token');
    check(h.length === 3 && h[2].msg.token === 'sesame', `token: Hello.token carries it (${h.map((x) => x.msg.token).join(',')})`);
    check(await waitText(page, /^$/, 2000), 'token: no message left once streaming');
    await page.close();
  }

  // 7b. A token in the link: used, then gone from the address bar and history, kept for the tab.
  {
    const page = await openPage(`${base}/?token=sesame&ws=${wsUrl('/ws-token')}`);
    check(await moveUntil(page, (c) => c.framesDecoded >= 3), 'token link: streams with the token from the URL');
    check(hellos('/ws-token').at(-1).msg.token === 'sesame', 'token link: Hello.token carries it');
    check(!/[?&]token=/.test(page.url()), `token link: the URL no longer holds it (${page.url()})`);
    const kept = await page.evaluate(() => sessionStorage.getItem('catgs.token'));
    check(kept === 'sesame', `token link: kept in sessionStorage (${kept})`);
    await page.close();
  }

  // 8. Server full with retry_after_ms 2500: countdown, retry at the hint, retry now, and no red
  //    text left over the live picture afterwards.
  {
    const page = await openPage(`${base}/?ws=${wsUrl('/ws-full')}`);
    check(await waitText(page, /server full, retrying in [1-3] s/), 'full: "server full, retrying in N s"');
    await shot(page, 'server_full');
    await waitFor(() => hellos('/ws-full').length >= 2, 6000);
    const [h1, h2] = hellos('/ws-full');
    const gap = h2 ? h2.at - h1.at : -1;
    check(gap >= 2300 && gap < 4500, `full: the second try waits for the 2.5 s hint (${gap} ms; backoff would be 1 s)`);
    check(await waitText(page, /server full/), 'full: refused again, still counting down');
    await page.click('#messages button[data-action=retry]');
    await waitFor(() => hellos('/ws-full').length >= 3, 2000);
    const h3 = hellos('/ws-full')[2];
    check(!!h3 && h3.at - h2.at < 2000, `full: "retry now" tries at once (${h3 ? h3.at - h2.at : '-'} ms after the last try)`);
    check(await moveUntil(page, (c) => c.framesDecoded >= 3), 'full: streams once there is room');
    await sleep(300);
    const t = await page.evaluate(() => window.catgs.overlayText());
    check(t === '', `full: nothing left on screen (${JSON.stringify(t)})`);
    await page.close();
  }

  // 8b. A scene loading on first use: the Hello asks for progress, the status line says
  //     "loading scene NAME: NN%", then the first view streams and the line goes.
  {
    const page = await openPage(`${base}/?ws=${wsUrl('/ws-loading')}`);
    check(await waitText(page, /loading scene mock: 42%/, 4000), 'loading: "loading scene mock: 42%" while it loads');
    const h = hellos('/ws-loading');
    check(h.length === 1 && h[0].msg.load_progress === true, 'loading: Hello.load_progress is set');
    check(await moveUntil(page, (c) => c.framesDecoded >= 3), 'loading: streams once the scene is there');
    await sleep(300);
    const t = await page.evaluate(() => window.catgs.overlayText());
    check(!/loading scene/.test(t), `loading: the loading line is gone (${JSON.stringify(t)})`);
    await page.close();
  }

  // 9. Server stopping (SHUTTING_DOWN, retry_after_ms 1200): "server stopping" when its reason
  //    does not say more (catgs-server's on SIGTERM or SIGINT), "server restarting" only when it
  //    says it restarts; both come back on their own.
  for (const [scenario, word] of [['/ws-stop', 'stopping'], ['/ws-restart', 'restarting']]) {
    const page = await openPage(`${base}/?ws=${wsUrl(scenario)}`);
    const said = await moveUntil(page, (c, w) => new RegExp(`server ${w}, reconnecting`).test(c.overlayText()), word);
    const text = await page.evaluate(() => window.catgs.overlayText());
    check(said && !new RegExp(word === 'stopping' ? 'restarting' : 'stopping').test(text), `${word}: "server ${word}, reconnecting" (${JSON.stringify(text)})`);
    if (word === 'stopping') await shot(page, 'server_stopping');
    check(await moveUntil(page, (c, n) => c.connected && n, true, 5000) && hellos(scenario).length >= 2, `${word}: reconnected after the hint`);
    await page.close();
  }

  // 9b. A draining server's Stats (drain_ms_left): the page says when this stream ends.
  {
    const page = await openPage(`${base}/?ws=${wsUrl('/ws-drain')}`);
    check(await moveUntil(page, (c) => /server stopping: this stream ends in 3 s/.test(c.overlayText())),
      'drain: "server stopping: this stream ends in 3 s" (a draining server cannot tell whether it comes back)');
    await shot(page, 'server_draining');
    await page.close();
  }

  // 10. Reset, shared links, help, fullscreen.
  {
    const target = { position: [0.25, -0.5, -3], orientation: [0.9800666, 0.1986693, 0, 0], fov: 40 };
    const q = `pos=${target.position.join(',')}&rot=${target.orientation.join(',')}&fov=${target.fov}`;
    const page = await openPage(`${base}/?token=abc&${q}`);
    await page.waitForFunction(() => window.catgs.connected, null, { timeout: 10000 });
    await sleep(300);
    const session = hellos('/ws').at(-1).session;
    const first = posesOf(session)[0];
    const near = (a, b, eps = 1e-6) => a.every((v, i) => Math.abs(v - b[i]) <= eps);
    check(!!first && near([first.position.x, first.position.y, first.position.z], target.position) &&
      near([first.orientation.w, first.orientation.x, first.orientation.y, first.orientation.z], target.orientation) &&
      Math.abs(first.vertical_fov_deg - target.fov) < 1e-9, `link: the server's first pose is the link's view (${JSON.stringify(first)})`);
    // Move, copy the link, open it: the new page's first pose is the moved view.
    await page.mouse.move(160, 120);
    await page.mouse.down();
    await page.mouse.move(200, 100, { steps: 4 });
    await page.mouse.up();
    await sleep(200);
    await page.click('#btn-link');
    await sleep(200);
    const moved = await page.evaluate(() => window.catgs.lastPoseSent);
    const copied = await page.evaluate(() => location.href);
    check(!copied.includes('token=') && new URL(copied).searchParams.get('scene') === 'mock', `link: the copied link names the scene, leaves the token out (${copied})`);
    const page2 = await openPage(copied);
    await page2.waitForFunction(() => window.catgs.connected, null, { timeout: 10000 });
    await sleep(300);
    const first2 = posesOf(hellos('/ws').at(-1).session)[0];
    check(!!first2 && near([first2.position.x, first2.position.y, first2.position.z], moved.position, 1e-5) &&
      near([first2.orientation.w, first2.orientation.x, first2.orientation.y, first2.orientation.z], moved.orientation, 1e-5),
    'link: "copy link" then opening it shows the same view');
    await page2.close();
    // A link to a view of another scene: said so, and the server's own start view instead.
    const page3 = await openPage(`${base}/?scene=garden&${q}`);
    await page3.waitForFunction(() => window.catgs.connected, null, { timeout: 10000 });
    await sleep(300);
    const first3 = posesOf(hellos('/ws').at(-1).session)[0];
    check(!!first3 && first3.position.z === -4 && /view of "garden"; this server shows "mock"/.test(await messageText(page3)),
      'link: a view of another scene is not applied, and the page says why');
    await page3.close();
    // Reset (key R and the button): back to the Welcome's initial pose.
    for (const how of ['key', 'button']) {
      await page.evaluate(() => window.catgs.setPose([1, 1, 1], [1, 0, 0, 0], 70));
      if (how === 'key') await page.keyboard.press('r');
      else await page.click('#btn-reset');
      await sleep(200);
      const p = await page.evaluate(() => window.catgs.lastPoseSent);
      check(near(p.position, [0, 0, -4]) && near(p.orientation, [1, 0, 0, 0]) && p.fovDeg === 50, `reset (${how}): the initial view is sent (${JSON.stringify(p)})`);
    }
    check(!(await page.evaluate(() => location.search)).includes('pos='), 'reset: the view leaves the address');
    // After a reset the page orbits around the Welcome's orbit centre (0, 0, 1), not the bounds'
    // centre (0, 0, 0), about its up, keeping the horizon level.
    {
      await page.mouse.move(160, 120);
      await page.mouse.down();
      await page.mouse.move(220, 120, { steps: 5 });
      await page.mouse.up();
      await sleep(200);
      const p = await page.evaluate(() => window.catgs.lastPoseSent);
      const from = (c) => Math.hypot(p.position[0] - c[0], p.position[1] - c[1], p.position[2] - c[2]);
      const [w, x, y, z] = p.orientation;
      const rightY = 2 * (x * y + w * z); // y of the camera's x axis (rotated [1, 0, 0])
      check(Math.abs(from([0, 0, 1]) - 5) < 1e-6 && Math.abs(from([0, 0, 0]) - 4) > 0.01 && Math.abs(rightY) < 1e-9,
        `orbit: around the Welcome's orbit centre about its up (${JSON.stringify(p)})`);
    }
    await page.keyboard.press('h');
    const help = await page.evaluate(() => ({ shown: !document.getElementById('helppanel').hidden, text: document.getElementById('helppanel').textContent }));
    check(help.shown && /Shift/.test(help.text) && /two fingers/.test(help.text) && /stats=1/.test(help.text), 'help: H opens the panel (keys, mouse, touch, Shift, ?stats=1)');
    await shot(page, 'help');
    await page.keyboard.press('h');
    await page.click('#btn-fullscreen');
    check(await page.waitForFunction(() => !!document.fullscreenElement, null, { timeout: 3000 }).then(() => true, () => false),
      `fullscreen: the button enters fullscreen (${await messageText(page)})`);
    await page.keyboard.press('f');
    check(await page.waitForFunction(() => !document.fullscreenElement, null, { timeout: 3000 }).then(() => true, () => false), 'fullscreen: F leaves it');
    check(!/FPS/.test(await page.evaluate(() => window.catgs.overlayText())) && await page.evaluate(() => document.getElementById('stats').hidden),
      'stats: hidden without ?stats=1');
    await page.close();
  }

  // 11. Camera paths: record through the panel, play back, export/import; a tour through 3 views.
  {
    const page = await openPage(`${base}/`);
    await page.waitForFunction(() => window.catgs.connected, null, { timeout: 10000 });
    await page.keyboard.press('p');
    await page.click('#btn-record');
    for (let i = 1; i <= 10; i++) {
      await page.evaluate((x) => window.catgs.setPose([x, 0, -4], [1, 0, 0, 0], 50), i * 0.1);
      await sleep(60);
    }
    await page.click('#btn-record');
    const rec = await page.evaluate(() => window.catgs.recording);
    check(rec && rec.length >= 10 && Math.abs(rec.at(-1).position[0] - 1) < 1e-9, `paths: recorded ${rec && rec.length} poses ending at x = 1`);
    const trace = await page.evaluate(() => window.catgs.exportTrace());
    check(/^catgs-trace 1\n/.test(trace) && trace.trim().split('\n').length === rec.length + 2, 'paths: exported as a catgs-trace, one line per pose');
    const camsJson = JSON.parse(await page.evaluate(() => window.catgs.exportCameras('path')));
    check(camsJson.length >= 2 && camsJson.every((c) => c.width === 320 && c.height === 240 && c.rotation.length === 3), `paths: exported as cameras.json (${camsJson.length} views)`);
    await page.evaluate(() => window.catgs.setPose([0, 0, -4], [1, 0, 0, 0], 50));
    await page.click('#btn-play-path');
    await page.waitForFunction(() => window.catgs.playing === null, null, { timeout: 5000 });
    const end = await page.evaluate(() => window.catgs.lastPoseSent);
    check(Math.abs(end.position[0] - 1) < 1e-9, `paths: playback ends on the recorded last pose (x = ${end.position[0]})`);
    // Tour: three waypoints; while it plays the page sends poses between them, and ends on the last.
    const keys = [[0, 0, -4], [1, 0, -3], [2, 0, -4]];
    for (const k of keys) {
      await page.evaluate((p) => window.catgs.setPose(p, [1, 0, 0, 0], 50), k);
      await page.click('#btn-add-waypoint');
    }
    const firstSeq = (await page.evaluate(() => window.catgs.lastPoseSent)).sequence;
    await page.click('#btn-play-tour');
    check(await page.evaluate(() => window.catgs.playing) === 'tour', 'tour: playing');
    await page.waitForFunction(() => window.catgs.playing === null, null, { timeout: 8000 });
    const s = hellos('/ws').at(-1).session;
    // The page sends the last pose in the step that ends the tour; it may still be on its way to
    // the mock server when `playing` reads null here.
    const sentLast = (await page.evaluate(() => window.catgs.lastPoseSent)).sequence;
    await waitFor(() => posesOf(s).some((p) => p.sequence >= sentLast), 3000);
    const tourPoses = posesOf(s).filter((p) => p.sequence > firstSeq);
    const last = tourPoses.at(-1);
    check(tourPoses.length > 20 && Math.abs(last.position.x - 2) < 1e-9 && Math.abs(last.position.z + 4) < 1e-9,
      `tour: ${tourPoses.length} poses sent, ending at the last waypoint`);
    check(tourPoses.some((p) => Math.abs(p.position.z + 3) < 0.02 && Math.abs(p.position.x - 1) < 0.02), 'tour: passes through the middle waypoint');
    // Import: the exported cameras.json comes back as waypoints; a bad file is named.
    const ok = await page.evaluate((t) => window.catgs.importText('c.json', t), JSON.stringify(camsJson));
    check(ok && (await page.evaluate(() => document.getElementById('paths-status').textContent)).includes(`${camsJson.length} waypoints`), 'import: cameras.json becomes waypoints');
    const bad = await page.evaluate(() => window.catgs.importText('bad.trace', 'catgs-trace 1\n1 2 3\n'));
    check(!bad && /bad\.trace: trace line 2: expected 14 fields/.test(await messageText(page)), 'import: a bad file is named with its line');
    await shot(page, 'paths_panel');
    await page.close();
  }

  // 11b. Quality menu: resolution scale sends Resize, a bitrate ceiling sends Quality (and the
  //      current pose again, which the rebuilt encoder answers with an IDR).
  {
    const page = await openPage(`${base}/`);
    await page.waitForFunction(() => window.catgs.connected, null, { timeout: 10000 });
    const session = hellos('/ws').at(-1).session;
    await page.click('#btn-quality');
    await page.selectOption('#quality-scale', '0.5');
    await page.selectOption('#quality-bitrate', '2000');
    await sleep(400);
    const mine = mock.received.filter((r) => r.session === session);
    const rz = mine.filter((r) => r.body === 'resize').at(-1);
    const q = mine.filter((r) => r.body === 'quality').at(-1);
    check(!!rz && rz.msg.viewport_width === 160 && rz.msg.viewport_height === 120, `quality: 50% resolution sends Resize 160x120 (${JSON.stringify(rz && rz.msg)})`);
    check(!!q && q.msg.max_bitrate_kbps === 2000, `quality: 2 Mbit/s sends Quality (${JSON.stringify(q && q.msg)})`);
    const after = mine.indexOf(q);
    check(mine.slice(after + 1).some((r) => r.body === 'pose'), 'quality: the current pose follows, for the rebuilt encoder\'s first frame');
    check((await page.evaluate(() => document.getElementById('quality-status').textContent)) === 'stream 160x120', 'quality: the panel shows the stream size');
    await page.close();
  }

  // 11c. Latency hiding: while the newest pose's frame is on its way, the last frame is shown
  // re-projected to it (a CSS matrix3d on the canvas); once that frame arrives, no transform.
  {
    const transformOf = (page) => page.evaluate(() => document.getElementById('view').style.transform);
    const turnRight = (page, angle) =>
      page.evaluate((a) => {
        const p = window.catgs.pose();
        // A turn about the camera's own down axis: forward swings right, the picture moves left.
        const [w, x, y, z] = p.orientation;
        const h = [Math.cos(a / 2), 0, Math.sin(a / 2), 0];
        const q = [
          w * h[0] - x * h[1] - y * h[2] - z * h[3],
          w * h[1] + x * h[0] + y * h[3] - z * h[2],
          w * h[2] - x * h[3] + y * h[0] + z * h[1],
          w * h[3] + x * h[2] - y * h[1] + z * h[0],
        ];
        return window.catgs.setPose(p.position, q, p.fovDeg);
      }, angle);
    // The page's own first Pose is answered; the camera stays still until the turn below.
    const firstFrame = async (page) => {
      const end = Date.now() + 8000;
      while (Date.now() < end && !(await page.evaluate(() => window.catgs.framesDecoded >= 1))) await sleep(50);
      return page.evaluate(() => window.catgs.framesDecoded >= 1);
    };
    const page = await openPage(`${base}/?ws=${wsUrl('/ws-hold')}`);
    check(await firstFrame(page), 'reproject: the held session shows its first frame');
    await sleep(200);
    check((await transformOf(page)) === '', 'reproject: no transform while the frame matches the camera');
    await turnRight(page, 0.05);
    await sleep(300);
    const t = await transformOf(page);
    const m = /^matrix3d\((.*)\)$/.exec(t);
    const v = m ? m[1].split(',').map(Number) : [];
    // The shift of the picture, CSS pixels: -f tan(0.05) at the stream's focal length, scaled to
    // the canvas's CSS size.
    const info = await page.evaluate(() => {
      const c = document.getElementById('view');
      return { w: c.width, h: c.height, cssW: c.clientWidth, cssH: c.clientHeight, fov: window.catgs.pose().fovDeg };
    });
    const f = info.h / (2 * Math.tan((info.fov * Math.PI) / 360));
    const want = -f * Math.tan(0.05) * (info.cssW / info.w);
    // Where the matrix (column-major, origin at the corner) takes the canvas centre.
    const [cx, cy] = [info.cssW / 2, info.cssH / 2];
    const shift = v.length === 16 ? (v[0] * cx + v[4] * cy + v[12]) / (v[3] * cx + v[7] * cy + v[15]) - cx : NaN;
    const rise = v.length === 16 ? (v[1] * cx + v[5] * cy + v[13]) / (v[3] * cx + v[7] * cy + v[15]) - cy : NaN;
    check(Math.abs(shift - want) < 0.05 * Math.abs(want) && Math.abs(rise) < 0.5,
      `reproject: a turn right moves the held frame's centre left by ${want.toFixed(1)} CSS px (${shift.toFixed(2)}, ${rise.toFixed(2)})`);
    // A larger turn uncovers the window's right part: it continues the frame's right edge
    // (clamp-to-edge, the backdrop behind the canvas), not black. Compared on screen: the
    // uncovered strip's colour, row by row, against the frame's last column.
    await turnRight(page, 0.3);
    await sleep(300);
    const png = (b64) => PNG.sync.read(Buffer.from(b64, 'base64'));
    const screen = png((await page.screenshot()).toString('base64'));
    const frame = png((await page.evaluate(() => window.catgs.snapshot())).split(',')[1]);
    const px = (img, x, y) => [...img.data.subarray((y * img.width + x) * 4, (y * img.width + x) * 4 + 3)];
    const rows = [105, 120, 135, 150, 165]; // between the toolbar and the hint
    // The canvas's right edge on screen at these rows (where the matrix takes x = cssW).
    const t2 = /^matrix3d\((.*)\)$/.exec(await transformOf(page))[1].split(',').map(Number);
    const edgeX = (y) => (t2[0] * info.cssW + t2[4] * y + t2[12]) / (t2[3] * info.cssW + t2[7] * y + t2[15]);
    const strip = rows.map((y) => {
      const x0 = Math.ceil(Math.max(...rows.map(edgeX))) + 4;
      const xs = Array.from({ length: info.cssW - 2 - x0 }, (_, i) => x0 + i);
      const mean = [0, 1, 2].map((c) => xs.reduce((a, x) => a + px(screen, x, y)[c], 0) / xs.length);
      // The frame's last column near that row (a turn about the camera's down axis stretches the
      // edge's rows a little): the closest colour of it.
      const fy = Math.round((y * frame.height) / info.cssH);
      const near = Array.from({ length: 13 }, (_, k) => px(frame, frame.width - 1, Math.min(frame.height - 1, Math.max(0, fy - 6 + k))));
      const diff = (e) => Math.max(...e.map((v, c) => Math.abs(v - mean[c])));
      const edge = near.reduce((a, e) => (diff(e) < diff(a) ? e : a));
      return { y, x0, mean: mean.map(Math.round), edge, off: Math.round(diff(edge)) };
    });
    const shown = await page.evaluate(() => !document.getElementById('backdrop').hidden);
    const darkStrip = strip.every((r) => Math.max(...r.mean) < 8);
    const matches = strip.filter((r) => r.off <= 30).length;
    check(shown && strip[0].x0 < info.cssW - 20 && !darkStrip && matches >= rows.length - 1,
      `reproject: the uncovered right part continues the frame's right edge, not black (${JSON.stringify(strip)})`);
    await shot(page, 'reproject_edge_fill');
    await page.close();
    const off = await openPage(`${base}/?reproject=0&ws=${wsUrl('/ws-hold')}`);
    check(await firstFrame(off), 'reproject=0: first frame');
    await turnRight(off, 0.05);
    await sleep(300);
    check((await transformOf(off)) === '', 'reproject=0: the frame is never transformed');
    await off.close();
    const live = await openPage(`${base}/?ws=${wsUrl('/ws')}`);
    check(await moveUntil(live, (c) => c.framesDecoded >= 2), 'reproject: a live session decodes');
    const seq = await turnRight(live, 0.05);
    const end = Date.now() + 5000;
    while (Date.now() < end && (await live.evaluate(() => window.catgs.lastFrame.poseSequence)) !== seq) await sleep(50);
    await sleep(100);
    check((await transformOf(live)) === '' && (await live.evaluate(() => document.getElementById('backdrop').hidden)),
      'reproject: the transform (and the edge behind it) goes once the frame of the new pose is shown');
    await live.close();
  }

  // 11c'. The depth warp (issue 91): a held frame whose depth grid puts its left part 2 units away
  // and its right part 20. A step sideways moves the left part about ten times as far as the right
  // (the plane through the orbit target, 5 away, would move both alike), the band between them
  // stretches over what the frame did not see, and nothing turns black.
  {
    const page = await openPage(`${base}/?ws=${wsUrl('/ws-hold-depth')}`);
    check(await moveUntil(page, (c) => c.framesDecoded >= 1), 'depth warp: the held frame');
    await sleep(300);
    const depths = await page.evaluate(() => {
      const c = document.getElementById('view');
      return [0.1, 0.9].map((f) => window.catgs.frameDepthAt(f * c.clientWidth, 0.5 * c.clientHeight));
    });
    check(Math.abs(depths[0] - 2) < 0.01 && Math.abs(depths[1] - 255 / 13) < 0.01,
      `depth warp: the grid reads 2 on the left, 19.6 (code 26) on the right without a round trip (${depths})`);
    const step = 0.1;
    await page.evaluate((s) => {
      const p = window.catgs.pose();
      const [w, x, y, z] = p.orientation; // the camera's right axis: q (1, 0, 0) q*
      const right = [1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)];
      window.catgs.setPose(p.position.map((v, i) => v + s * right[i]), p.orientation, p.fovDeg);
    }, step);
    await sleep(400);
    const overlay = await page.evaluate(() => {
      const c = document.querySelector('#view + canvas');
      return c ? { hidden: c.hidden, w: c.width, h: c.height } : null;
    });
    check(!!overlay && !overlay.hidden && overlay.w === 160, `depth warp: the mesh canvas shows over the view (${JSON.stringify(overlay)})`);
    const png = (b64) => PNG.sync.read(Buffer.from(b64, 'base64'));
    const screen = png((await page.screenshot()).toString('base64'));
    const frame = png((await page.evaluate(() => window.catgs.snapshot())).split(',')[1]);
    const info = await page.evaluate(() => {
      const c = document.getElementById('view');
      return { cssW: c.clientWidth, cssH: c.clientHeight, fov: window.catgs.pose().fovDeg };
    });
    const k = info.cssW / 160; // CSS pixels a frame pixel
    const f = 120 / (2 * Math.tan((info.fov * Math.PI) / 360));
    // Mean absolute difference of the screen against the frame moved left by `shift` frame pixels,
    // over screen columns of frame x in [x0, x1) and a band of rows.
    const mad = (shift, x0, x1) => {
      let sum = 0;
      let n = 0;
      for (let y = Math.round(0.45 * info.cssH); y < Math.round(0.75 * info.cssH); y += 3) {
        for (let xs = Math.round(x0 * k); xs < Math.round(x1 * k); xs += 2) {
          const fx = Math.min(159, Math.max(0, Math.round(xs / k + shift - 0.5)));
          const fy = Math.min(119, Math.round((y * 120) / info.cssH - 0.5));
          for (let c = 0; c < 3; c++) sum += Math.abs(screen.data[(y * screen.width + xs) * 4 + c] - frame.data[(fy * 160 + fx) * 4 + c]);
          n += 3;
        }
      }
      return sum / n;
    };
    const near = (f * step) / 2; // the left part's shift, frame pixels
    const far = (f * step) / (255 / 13);
    const plane = (f * step) / 5;
    const left = { near: mad(near, 8, 52), plane: mad(plane, 8, 52) };
    const right = { far: mad(far, 108, 150), plane: mad(plane, 108, 150) };
    check(left.near < left.plane && right.far < right.plane,
      `depth warp: the near part moved ${near.toFixed(1)} px, the far part ${far.toFixed(1)}, not the plane's ${plane.toFixed(1)} ` +
      `(mean differences ${JSON.stringify({ left, right })})`);
    // The band the step uncovers, between the near part's right edge and the far part (frame x 56
    // to 104 in the rows above: no dark content in the frame there), is the stretched frame.
    let dark = 0;
    let seen = 0;
    for (let y = Math.round(0.45 * info.cssH); y < Math.round(0.75 * info.cssH); y++) {
      for (let xs = Math.round(56 * k); xs < Math.round(104 * k); xs++, seen++) {
        const p = (y * screen.width + xs) * 4;
        if (Math.max(screen.data[p], screen.data[p + 1], screen.data[p + 2]) < 24) dark++;
      }
    }
    check(seen > 1000 && dark === 0, `depth warp: no black where the step uncovered the far part (${dark} dark of ${seen} pixels)`);
    await shot(page, 'depth_warp_step');
    await page.close();
  }

  // 11d. Scene picker: the server lists three scenes; picking one reopens the page on it and its
  // Hello names it. A scene whose size is not known yet (gaussians: null) shows its name alone.
  {
    const page = await openPage(`${base}/?ws=${wsUrl('/ws')}`);
    check(await moveUntil(page, (c) => c.framesDecoded >= 1), 'scenes: first frame');
    const opts = await page.evaluate(() => {
      const p = document.getElementById('scene-picker');
      return { hidden: p.hidden, names: [...p.options].map((o) => o.value), labels: [...p.options].map((o) => o.textContent), value: p.value };
    });
    check(!opts.hidden && opts.names.join(',') === 'mock,garden,city' && opts.value === 'mock',
      `scenes: the picker lists mock, garden and city, mock chosen (${JSON.stringify(opts)})`);
    check(opts.labels.join('|') === 'mock (0.15 M)|garden (5.83 M)|city',
      `scenes: sizes in millions, a scene of unknown size by name alone (${JSON.stringify(opts.labels)})`);
    await shot(page, 'scene_picker');
    const before = hellos('/ws').length;
    await Promise.all([page.waitForNavigation(), page.selectOption('#scene-picker', 'garden')]);
    check(new URL(page.url()).searchParams.get('scene') === 'garden', `scenes: the page reopened with ?scene=garden (${page.url()})`);
    const end = Date.now() + 8000;
    while (Date.now() < end && hellos('/ws').length === before) await sleep(50);
    const last = hellos('/ws').at(-1);
    check(last && last.msg.scene === 'garden', `scenes: the new session's Hello names garden (${last && JSON.stringify(last.msg.scene)})`);
    await page.close();
  }

  // 11e. ?scene= naming a scene the server does not have: a plain sentence and the scene picker
  //      (filled from GET /scenes) in the message, no retry loop; choosing a scene opens it.
  {
    const page = await openPage(`${base}/?scene=nosuchscene&ws=${wsUrl('/ws')}`);
    const tries = () => hellos('/ws').filter((h) => h.msg.scene === 'nosuchscene').length;
    check(await waitText(page, /^There is no scene named 'nosuchscene' on this server; it has mock, garden, city\. Choose one:/), `no scene: said in words (${JSON.stringify(await messageText(page))})`);
    await page.waitForFunction(() => document.querySelectorAll('#messages #scene-picker option').length >= 3, null, { timeout: 5000 }).catch(() => {});
    const ui = await page.evaluate(() => {
      const p = document.querySelector('#messages #scene-picker');
      return p && { shown: !p.hidden && p.getBoundingClientRect().height > 0, value: p.value, label: p.selectedOptions[0]?.textContent,
        names: [...p.options].filter((o) => o.value).map((o) => o.value), cls: p.closest('.msg').className };
    });
    check(!!ui && ui.shown && ui.names.join(',') === 'mock,garden,city' && ui.value === '' && /choose a scene/.test(ui.label),
      `no scene: the picker in the message lists the server's scenes, none chosen (${JSON.stringify(ui)})`);
    check(!!ui && !/error/.test(ui.cls) && !/reconnecting|rejected|it has:/.test(await messageText(page)), 'no scene: no red technical line, no countdown');
    await shot(page, 'no_such_scene');
    await sleep(3000);
    check(tries() === 1, `no scene: no retries (${tries()} Hellos in 3 s)`);
    await Promise.all([page.waitForNavigation(), page.selectOption('#scene-picker', 'garden')]);
    check(new URL(page.url()).searchParams.get('scene') === 'garden', `no scene: choosing garden reopens the page on it (${page.url()})`);
    await page.waitForFunction(() => window.catgs.connected, null, { timeout: 10000 });
    await page.close();
  }

  // 11f. Notes: Esc closes the new hotspot's form (the next key is a key, not typed into it), and
  //      the Notes panel, closed while a hotspot is placed or a distance measured, comes back when
  //      that ends: placed, cancelled, Esc. Panels never cover the stats (?stats=1).
  {
    const page = await openPage(`${base}/?stats=1&ws=${wsUrl('/ws')}`);
    check(await moveUntil(page, (c) => c.framesDecoded >= 2), 'notes: streams');
    const vis = (id) => page.evaluate((i) => !document.getElementById(i).hidden, id);
    await page.click('#btn-notes');
    await page.click('#btn-add-hotspot');
    check(!(await vis('notes')), 'notes: Add hotspot closes the panel (the scene takes the click)');
    await page.mouse.click(100, 150);
    await page.waitForSelector('#hotspot-form:not([hidden])', { timeout: 5000 });
    await page.keyboard.type('Ti');
    await shot(page, 'hotspot_form');
    await page.keyboard.press('Escape');
    check(!(await vis('hotspot-form')) && (await vis('notes')), 'notes: Esc in the new hotspot form closes it, the Notes panel is back');
    await page.keyboard.press('m');
    const after = await page.evaluate(() => ({ title: document.getElementById('hotspot-title').value, mode: window.catgs.notes.mode }));
    check(after.title === '' && after.mode === 'measure', `notes: the next M measures, nothing typed into the form (${JSON.stringify(after)})`);
    check(!(await vis('notes')), 'notes: measuring closes the panel');
    await page.keyboard.press('Escape');
    check((await vis('notes')) && (await page.evaluate(() => window.catgs.notes.mode)) === null, 'notes: Esc ends measuring, the panel is back');
    await page.click('#btn-measure');
    await page.mouse.click(100, 150);
    await page.mouse.click(200, 100);
    await page.waitForFunction(() => window.catgs.notes.mode === null, null, { timeout: 5000 }).catch(() => {});
    check(await vis('notes'), 'notes: the panel is back once the two points are measured');
    await page.click('#btn-add-hotspot');
    await page.mouse.click(100, 150);
    await page.waitForSelector('#hotspot-form:not([hidden])', { timeout: 5000 });
    await page.click('#btn-cancel-hotspot');
    check(!(await vis('hotspot-form')) && (await vis('notes')) && (await page.evaluate(() => window.catgs.notes.mode)) === null,
      'notes: Cancel closes the form and ends adding, the panel is back');
    await page.click('#btn-add-hotspot');
    await page.mouse.click(100, 150);
    await page.waitForSelector('#hotspot-form:not([hidden])', { timeout: 5000 });
    await page.fill('#hotspot-title', 'Pole');
    await page.click('#hotspot-form button[type=submit]');
    const n = await page.evaluate(() => window.catgs.notes);
    check(n.hotspots.length === 1 && n.hotspots[0].title === 'Pole' && (await vis('notes')), 'notes: a placed hotspot, the panel is back');
    // Esc in another panel's field (the scale) closes that panel.
    await page.focus('#scale-metres');
    await page.keyboard.press('Escape');
    check(!(await vis('notes')), 'notes: Esc in the scale field closes the Notes panel');
    // No panel covers the stats box (a 320x240 window: they share columns).
    await page.waitForFunction(() => /server:/.test(document.getElementById('stats').textContent), null, { timeout: 5000 }).catch(() => {});
    const overlaps = [];
    for (const [panel, open] of [['helppanel', 'h'], ['paths', 'p'], ['notes', 'n'], ['quality', null]]) {
      if (open) await page.keyboard.press(open);
      else await page.click('#btn-quality');
      await sleep(100);
      const r = await page.evaluate((id) => {
        const box = (el) => { const b = el.getBoundingClientRect(); return { l: b.left, t: b.top, r: b.right, b: b.bottom }; };
        return { panel: box(document.getElementById(id)), stats: box(document.getElementById('stats')), shown: !document.getElementById(id).hidden };
      }, panel);
      const over = r.panel.l < r.stats.r && r.stats.l < r.panel.r && r.panel.t < r.stats.b && r.stats.t < r.panel.b;
      if (!r.shown || over || r.panel.b > 240) overlaps.push({ panel, ...r });
      if (panel === 'notes') await shot(page, 'notes_panel_under_stats');
      await page.keyboard.press('Escape');
    }
    check(overlaps.length === 0, `stats: help, paths, notes and quality open below the stats box, within the window (${JSON.stringify(overlaps)})`);
    await page.close();
  }

  // 12. A phone: 390x844 CSS pixels at DPR 3 with touch. The stream is capped (886x1920, not
  //     1170x2532), nothing on screen is cut off, and the hint speaks of fingers.
  {
    await context.close();
    context = null;
    const phoneProfile = mkdtempSync(path.join(os.tmpdir(), 'catgs-mock-phone-'));
    const phone = await launch(phoneProfile, { viewport: { width: 390, height: 844 }, deviceScaleFactor: 3, isMobile: true, hasTouch: true });
    try {
      const page = await openPage(`${base}/?stats=1`, phone);
      check(await moveUntil(page, (c) => c.framesDecoded >= 3), 'phone: streams');
      const v = await page.evaluate(() => window.catgs.viewport);
      const hello = hellos('/ws').at(-1).msg;
      check(v.width === 886 && v.height === 1920 && hello.viewport_width === 886 && hello.viewport_height === 1920,
        `phone: Hello asks for 886x1920 at DPR 3 (${hello.viewport_width}x${hello.viewport_height})`);
      await page.evaluate(() => window.catgs.importText('x.trace', 'junk')); // a long message too
      // The toolbar: one row of buttons a finger can hit (40 CSS px tall at least); Link, Paths,
      // Quality and the scene picker under More.
      const bar = () => page.evaluate(() => {
        const items = [...document.querySelectorAll('#toolbar > *')].filter((el) => getComputedStyle(el).display !== 'none')
          .map((el) => { const r = el.getBoundingClientRect(); return { id: el.id, top: Math.round(r.top), h: Math.round(r.height * 10) / 10, right: r.right }; });
        return { items, open: document.getElementById('toolbar').classList.contains('menu-open') };
      });
      const row = await bar();
      const rowOk = row.items.length >= 5 && row.items.every((b) => b.h >= 40 && b.top === row.items[0].top && b.right <= 390) &&
        row.items.some((b) => b.id === 'btn-menu') && !row.items.some((b) => ['btn-paths', 'btn-link', 'btn-quality'].includes(b.id));
      check(rowOk, `phone: toolbar buttons at least 40 px tall, on one row (${JSON.stringify(row.items)})`);
      const statsBox = () => page.evaluate(() => { const r = document.getElementById('stats').getBoundingClientRect(); return { l: r.left, t: r.top, r: r.right, b: r.bottom }; });
      const panelClear = async (id) => {
        const r = await page.evaluate((i) => { const b = document.getElementById(i).getBoundingClientRect(); return { l: b.left, t: b.top, r: b.right, b: b.bottom }; }, id);
        const st = await statsBox();
        const over = r.l < st.r && st.l < r.r && r.t < st.b && st.t < r.b;
        return { ok: !over && r.b <= 844, panel: r, stats: st };
      };
      await page.tap('#btn-menu');
      const menu = await bar();
      check(menu.open && ['scene-picker', 'btn-link', 'btn-paths', 'btn-quality'].every((id) => menu.items.some((b) => b.id === id && b.h >= 40)),
        `phone: More opens the menu: scenes, Link, Paths, Quality (${JSON.stringify(menu.items.map((b) => b.id))})`);
      await shot(page, 'phone_dpr3_menu');
      await page.tap('#btn-paths');
      const paths = await panelClear('paths');
      check(!(await bar()).open && (await page.isVisible('#paths')) && paths.ok, `phone: Paths from the menu opens its panel below the stats, the menu closed (${JSON.stringify(paths)})`);
      await shot(page, 'phone_dpr3_paths');
      // The stats grow once the server's Stats come (3 more lines): the open panel moves down.
      await page.waitForFunction(() => /rtt/.test(document.getElementById('stats').textContent), null, { timeout: 5000 }).catch(() => {});
      await sleep(100);
      const grown = await panelClear('paths');
      check(grown.ok && grown.stats.b - grown.stats.t > paths.stats.b - paths.stats.t - 1, `phone: as the stats grow, the open panel stays below them (${JSON.stringify(grown)})`);
      await page.tap('#btn-help');
      const helpClear = await panelClear('helppanel');
      check(helpClear.ok, `phone: the help panel does not cover the stats (${JSON.stringify(helpClear)})`);
      const boxes = await page.evaluate(() => [...document.querySelectorAll('.overlay:not([hidden])')].map((el) => {
        const r = el.getBoundingClientRect();
        return { id: el.id, left: r.left, top: r.top, right: r.right, bottom: r.bottom, sw: el.scrollWidth, cw: el.clientWidth };
      }));
      const clipped = boxes.filter((b) => b.left < 0 || b.top < 0 || b.right > 390 || b.bottom > 844 || b.sw > b.cw + 1);
      check(boxes.length >= 4 && clipped.length === 0, `phone: no overlay cut off (${JSON.stringify(clipped.length ? clipped : boxes.map((b) => b.id))})`);
      const hint = await page.evaluate(() => document.getElementById('hint').textContent);
      check(/finger/.test(hint) && !/wheel|WASD/.test(hint), `phone: touch hint (${hint})`);
      await shot(page, 'phone_dpr3_help');
      await page.tap('#btn-help');
      // One finger drags through CDP touch events: the camera orbits.
      const before = await page.evaluate(() => window.catgs.lastPoseSent.sequence);
      const cdp = await phone.newCDPSession(page);
      const touch = (type, x, y) => cdp.send('Input.dispatchTouchEvent', { type, touchPoints: type === 'touchEnd' ? [] : [{ x, y }] });
      await touch('touchStart', 200, 500);
      for (let i = 1; i <= 5; i++) await touch('touchMove', 200 + i * 10, 500);
      await touch('touchEnd');
      await sleep(300);
      check((await page.evaluate(() => window.catgs.lastPoseSent.sequence)) > before, 'phone: a one-finger drag moves the camera');
      await shot(page, 'phone_dpr3');
      await page.close();
    } finally {
      await phone.close();
      rmSync(phoneProfile, { recursive: true, force: true });
    }
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
