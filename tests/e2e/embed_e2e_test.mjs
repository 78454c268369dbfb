// The viewer embedded in another site (issue 63): fixtures/embed/index.html, a made-up magazine
// page (header, sidebar, article) with a <catgs-viewer> in a 480x300 box, served from another
// origin (http://embed.test:PORT, a node static server here; Chromium maps the name to loopback)
// than the real catgs-server, which runs with --allowed-origins for it and a viewer token. The
// page imports viewer/viewer.js from the catgs server (a cross-origin module: the server's CORS
// header).
//
// Checked, each of which could be false: the viewer's `connected` event, frames (frame events,
// a canvas that is not blank), a `stats` event, setPose changes the picture, playPath moves the
// camera through its views, the host page's layout intact (the box the page gave, its header and
// sidebar where they were, none of the full page's toolbar or hook), keys on the host page left
// to it, and `error` with the server's reason for a wrong token and for a scene the server lacks
// (and the right token again streams). The element's own box says each in words (issue 75), as
// it does for a browser without WebCodecs, for the same page on a site --allowed-origins lacks
// (http://other.test:PORT: the element keeps its box and says why) and for a server stopped with
// Ctrl-C, and a host page's `messages` replace them. The page opened while the server is down,
// with the README's loader inline: the box counts down, the site's error listener hears it, and
// the view streams once the server is back. Screenshots: embed.png, embed_error.png,
// embed_unsupported.png, embed_refused.png, embed_gone.png, embed_down.png, embed_back.png.
//
// usage: node embed_e2e_test.mjs --server PATH/catgs-server [--repo ROOT] [--out DIR]
// Exit codes: 0 pass, 1 fail, 77 skipped (no chromium / npm deps / server binary).
import { mkdtempSync, readFileSync, writeFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { BrowserTestRun, browserOrSkip, CHROMIUM_ARGS, freePort, sleep, waitFor } from './harness.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const repo = path.resolve(args.repo || path.join(here, '../..'));
const serverBin = args.server || process.env.CATGS_SERVER;
const outDir = path.resolve(args.out || mkdtempSync(path.join(os.tmpdir(), 'catgs-embed-out-')));
const { chromium, chromiumPath } = browserOrSkip(here, { 'catgs-server': serverBin });
const { PNG } = createRequire(import.meta.url)('pngjs');
const run = new BrowserTestRun('embed', { serverBin, webRoot: path.join(repo, 'web_client'), outDir });
const { log, check } = run;
const TOKEN = 'embed-viewer-token';
const BOX = { width: 480, height: 300 }; // the fixture's CSS for the viewer

// The site: the fixture folder over HTTP, the page with the catgs server's host and token filled
// in at /; at /loader the same page embedding as the README says for a server that may be down:
// the viewer's loader (web_client/viewer/loader.js) inline instead of the module import.
function startSite(port, catgsHost) {
  const page = readFileSync(path.join(here, 'fixtures/embed/index.html'), 'utf8')
    .replaceAll('CATGS_HOST', catgsHost).replaceAll('CATGS_TOKEN', TOKEN);
  const importLine = `    import 'http://${catgsHost}/viewer/viewer.js';\n`;
  if (!page.includes(importLine)) throw new Error('the fixture no longer imports the viewer as the test expects');
  const loader = readFileSync(path.join(repo, 'web_client/viewer/loader.js'), 'utf8')
    .replace("})('SRC');", `})('http://${catgsHost}/viewer/viewer.js');`);
  const loaderPage = page.replace(importLine, '').replace('  <script type="module">', `  <script>\n${loader}</script>\n  <script type="module">`);
  const server = http.createServer((req, res) => {
    const at = new URL(req.url, 'http://x').pathname;
    if (at !== '/' && at !== '/loader') return res.writeHead(404).end();
    res.writeHead(200, { 'content-type': 'text/html; charset=utf-8' }).end(at === '/' ? page : loaderPage);
  });
  return new Promise((resolve) => server.listen(port, '127.0.0.1', () => resolve(server)));
}

// Grey levels of a PNG data URL: { mean, sd, distinct } and the pixels (for differences).
function picture(dataUrl) {
  const png = PNG.sync.read(Buffer.from(dataUrl.split(',')[1], 'base64'));
  const grey = new Float64Array(png.width * png.height);
  for (let i = 0; i < grey.length; i++) grey[i] = (png.data[4 * i] + png.data[4 * i + 1] + png.data[4 * i + 2]) / 3;
  const mean = grey.reduce((a, b) => a + b, 0) / grey.length;
  const sd = Math.sqrt(grey.reduce((a, v) => a + (v - mean) ** 2, 0) / grey.length);
  return { width: png.width, height: png.height, mean, sd, distinct: new Set(grey.map(Math.round)).size, grey };
}

// The share of pixels whose grey level differs by more than 24 (of 255) between two pictures.
const gap = (p, q) => Math.hypot(...p.map((v, i) => v - q[i]));
const changed = (a, b) => a.grey.reduce((n, v, i) => n + (Math.abs(v - b.grey[i]) > 24 ? 1 : 0), 0) / a.grey.length;

// In the page, before anything runs: every event of a <catgs-viewer> logged (capture on the
// window sees them whether or not they bubble), frames counted.
function recordEvents() {
  const log = (window.embedEvents = { frames: 0, all: [] });
  for (const type of ['connected', 'frame', 'stats', 'error', 'status', 'disconnected']) {
    window.addEventListener(type, (e) => {
      if (!e.target || e.target.localName !== 'catgs-viewer') return;
      if (type === 'frame') log.frames++;
      else log.all.push({ type, detail: JSON.parse(JSON.stringify(e.detail)), at: performance.now() });
    }, true);
  }
}

const events = (page, type) => page.evaluate((t) => window.embedEvents.all.filter((e) => e.type === t), type);
const frames = (page) => page.evaluate(() => window.embedEvents.frames);
const snapshot = async (page) => picture(await page.evaluate(() => document.getElementById('bike').snapshot()));

// Sets the pose through the element; resolves once a frame of that pose was drawn.
async function poseAndWait(page, spec) {
  const seq = await page.evaluate((s) => document.getElementById('bike').setPose(s), spec);
  await waitFor(`the frame of pose ${seq}`, () => page.evaluate((q) => {
    const v = document.getElementById('bike').viewer;
    return v.lastFrame && v.lastFrame.poseSequence >= q;
  }, seq), 30000);
  await sleep(300); // a refine frame of the same pose may follow
  return seq;
}

async function main() {
  const sitePort = await freePort();
  const siteOrigin = `http://embed.test:${sitePort}`;
  const otherOrigin = `http://other.test:${sitePort}`; // the same page on a site the server does not list
  const tokenFile = path.join(mkdtempSync(path.join(os.tmpdir(), 'catgs-embed-tok-')), 'tokens');
  writeFileSync(tokenFile, `viewer ${TOKEN}\n`);
  const scene = path.join(repo, 'assets/scenes/biker.compressed.ply');
  return run.main(chromium, chromiumPath, {
    viewport: { width: 1000, height: 560 },
    // embed.test is loopback to Chromium; WebCodecs needs a secure context, which plain http on a
    // name other than localhost is not: this test's origin counts as one.
    args: [...CHROMIUM_ARGS, '--host-resolver-rules=MAP embed.test 127.0.0.1, MAP other.test 127.0.0.1',
      `--unsafely-treat-insecure-origin-as-secure=${siteOrigin},${otherOrigin}`],
  }, async (context) => {
    const base = await run.startServer(['--scene', scene, '--token-file', tokenFile, '--allowed-origins', siteOrigin]);
    const site = await startSite(sitePort, new URL(base).host);
    try {
      await embedded(context, base, siteOrigin, otherOrigin, tokenFile);
    } finally {
      site.close();
    }
  });
}

async function embedded(context, base, siteOrigin, otherOrigin, tokenFile) {
  // The server's side of the cross-origin import: CORS for every site (the files are public), and
  // a site that may not open a session is told so.
  const cors = async (origin) => {
    const h = (await fetch(`${base}/viewer/viewer.js`, { headers: { Origin: origin } })).headers;
    return `${h.get('access-control-allow-origin')} ${h.get('catgs-session-origin')}`;
  };
  check(await cors(siteOrigin) === `${siteOrigin} null` && (await cors(otherOrigin)) === `${otherOrigin} refused`,
    `viewer/viewer.js carries Access-Control-Allow-Origin for ${siteOrigin} and for ${otherOrigin}, the latter with catgs-session-origin: refused`);

  const page = await context.newPage();
  page.on('console', (m) => run.pageLog.push(`console.${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => run.pageLog.push(`pageerror: ${e.message}`));
  await page.addInitScript(recordEvents);
  await page.goto(`${siteOrigin}/`);
  await waitFor('the connected event', async () => (await events(page, 'connected')).length > 0, 60000);
  const [connected] = await events(page, 'connected');
  const w = connected.detail.welcome;
  log(`connected: scene ${w.scene_name}, ${w.width}x${w.height}, codec ${w.codec}, orbit centre ${JSON.stringify(w.orbit_centre)}`);
  check(w.scene_name === 'biker', `connected fired with the Welcome (scene ${w.scene_name})`);
  check(w.width === BOX.width && w.height === BOX.height, `the stream has the box's size (${w.width}x${w.height}, box ${BOX.width}x${BOX.height})`);
  await waitFor('the first frame', async () => (await frames(page)) > 0, 60000);

  // ---- the host page's layout, as the site made it ----
  const layout = await page.evaluate(() => {
    const box = (el) => {
      const r = el.getBoundingClientRect();
      return { l: Math.round(r.left), t: Math.round(r.top), r: Math.round(r.right), b: Math.round(r.bottom) };
    };
    const el = document.getElementById('bike');
    const canvas = el.shadowRoot.querySelector('canvas.view');
    return {
      viewer: { w: el.clientWidth, h: el.clientHeight, ...box(el) },
      canvas: { w: canvas.clientWidth, h: canvas.clientHeight },
      header: box(document.getElementById('site-header')),
      sidebar: box(document.getElementById('sidebar')),
      article: box(document.getElementById('article')),
      toolbar: !!document.getElementById('toolbar') || !!el.shadowRoot.querySelector('nav, button, #toolbar, .panel'),
      hook: typeof window.catgs,
      status: document.getElementById('viewer-status').textContent,
    };
  });
  log(`layout: ${JSON.stringify(layout)}`);
  check(layout.viewer.w === BOX.width && layout.viewer.h === BOX.height && layout.canvas.w === BOX.width && layout.canvas.h === BOX.height,
    `the viewer fills the box the page gave it (${layout.viewer.w}x${layout.viewer.h}, canvas ${layout.canvas.w}x${layout.canvas.h})`);
  check(layout.header.t === 0 && layout.sidebar.t >= layout.header.b && layout.sidebar.r < layout.article.l &&
    layout.viewer.l >= layout.article.l && layout.viewer.t > layout.article.t && layout.viewer.r <= layout.article.r,
  'the site\'s layout is intact: header on top, sidebar left of the article, the viewer inside the article');
  check(!layout.toolbar && layout.hook === 'undefined', 'none of the full page: no toolbar, no panels, no window.catgs');
  check(layout.status === 'showing biker', `the site's own script heard connected ("${layout.status}")`);

  // ---- frames and stats ----
  const c = w.orbit_centre;
  const centre = [c.x, c.y, c.z];
  const p0 = w.initial_pose.position;
  const from = [p0.x, p0.y, p0.z];
  // Views around the orbit centre at the first view's distance: a quarter turn apart.
  const d = Math.hypot(from[0] - centre[0], from[1] - centre[1], from[2] - centre[2]);
  const up = [w.up.x, w.up.y, w.up.z];
  const around = (angle) => {
    // Any two directions across `up`, then the point on that circle.
    const a = Math.abs(up[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
    const dot = a[0] * up[0] + a[1] * up[1] + a[2] * up[2];
    const e1 = a.map((v, i) => v - dot * up[i]);
    const n1 = Math.hypot(...e1);
    const u = e1.map((v) => v / n1);
    const v = [up[1] * u[2] - up[2] * u[1], up[2] * u[0] - up[0] * u[2], up[0] * u[1] - up[1] * u[0]];
    return centre.map((x, i) => x + d * (Math.cos(angle) * u[i] + Math.sin(angle) * v[i]) + 0.2 * d * up[i]);
  };
  await poseAndWait(page, { position: around(0), lookAt: centre });
  const framesBefore = await frames(page);
  const a = await snapshot(page);
  for (let i = 1; i <= 3; i++) await poseAndWait(page, { position: around(0.05 * i), lookAt: centre });
  const framesAfter = await frames(page);
  log(`picture A: ${a.width}x${a.height}, mean ${a.mean.toFixed(1)}, sd ${a.sd.toFixed(1)}, ${a.distinct} grey levels`);
  check(framesAfter - framesBefore >= 3, `frame events keep coming as the pose moves (${framesAfter - framesBefore} for 3 poses)`);
  check(a.width === BOX.width && a.sd > 8 && a.distinct > 40, `the canvas is not blank (sd ${a.sd.toFixed(1)}, ${a.distinct} grey levels)`);
  await waitFor('a stats event', async () => (await events(page, 'stats')).length > 0, 10000).catch(() => {});
  const stats = await events(page, 'stats');
  const last = stats.length ? stats[stats.length - 1].detail : null;
  check(!!last && last.server.frames_sent >= 0 && 'render_ms_mean' in last.server && last.framesDecoded > 0,
    `stats events arrive (${stats.length}; the last: ${last ? JSON.stringify({ frames_sent: last.server.frames_sent, render_ms_mean: last.server.render_ms_mean, rttMs: last.rttMs }) : 'none'})`);

  // ---- setPose: another side of the scene, another picture ----
  // The same pose again (a control: the measure of change reads ~0 for an unchanged view).
  const a2 = await snapshot(page);
  await poseAndWait(page, { position: around(0.15), lookAt: centre });
  const same = changed(a2, await snapshot(page));
  await poseAndWait(page, { position: around(Math.PI / 2), lookAt: centre });
  const b = await snapshot(page);
  const ab = changed(a2, b);
  check(same < 0.002 && ab > 0.02 && ab > 10 * same,
    `setPose to a quarter turn away changes the picture (${(100 * ab).toFixed(1)}% of the pixels; the same pose again: ${(100 * same).toFixed(2)}%)`);
  await run.shot(page, 'embed.png');

  // ---- playPath: through three views, the camera moves and ends at the last ----
  const keys = [0.6, 1.2, 1.8].map((t) => ({ position: around(Math.PI / 2 + t), lookAt: centre }));
  const played = await page.evaluate(async (ks) => {
    const el = document.getElementById('bike');
    const seen = [];
    const timer = setInterval(() => seen.push(el.pose().position), 100);
    const framesAt = window.embedEvents.frames;
    const done = await el.playPath(ks, { secondsPerView: 1 });
    clearInterval(timer);
    return { done, seen, end: el.pose().position, frames: window.embedEvents.frames - framesAt, playing: el.playing };
  }, keys);
  const distinct = new Set(played.seen.map((p) => p.map((v) => v.toFixed(3)).join(','))).size;
  const endGap = Math.hypot(...played.end.map((v, i) => v - keys[2].position[i]));
  log(`playPath: resolved ${played.done}, ${played.seen.length} samples, ${distinct} distinct positions, ${played.frames} frames, end ${endGap.toExponential(2)} from the last view`);
  check(played.done === true && played.playing === null, 'playPath resolves true at its end');
  check(distinct >= 8 && endGap < 1e-6 * (1 + d) && played.frames >= 2, `playPath moves the camera through its views (${distinct} positions, ${played.frames} frames)`);
  await sleep(500);
  const bc = changed(b, await snapshot(page));
  check(bc > 0.02, `the picture after the path differs from before it (${(100 * bc).toFixed(1)}% of the pixels)`);

  // ---- keys: the host page's own until the view has the focus ----
  const before = await page.evaluate(() => document.getElementById('bike').pose().position);
  await page.click('#article h2');
  await page.keyboard.down('KeyW');
  await sleep(400);
  await page.keyboard.up('KeyW');
  const unmoved = await page.evaluate(() => document.getElementById('bike').pose().position);
  await page.click('#bike');
  await page.keyboard.down('KeyW');
  await sleep(400);
  await page.keyboard.up('KeyW');
  const moved = await page.evaluate(() => document.getElementById('bike').pose().position);
  check(gap(before, unmoved) === 0 && gap(unmoved, moved) > 0,
    `W on the host page leaves the camera alone; with the view focused it flies (${gap(unmoved, moved).toFixed(3)} units)`);

  // ---- controls="off": the page alone moves the camera ----
  const viewerConnected = async (n) => waitFor('connected again', async () => (await events(page, 'connected')).length > n, 30000);
  let n = (await events(page, 'connected')).length;
  await page.evaluate(() => document.getElementById('bike').setAttribute('controls', 'off'));
  await viewerConnected(n);
  const still = await page.evaluate(() => document.getElementById('bike').pose().position);
  const r = await page.evaluate(() => {
    const b = document.getElementById('bike').getBoundingClientRect();
    return { x: b.left + b.width / 2, y: b.top + b.height / 2 };
  });
  await page.mouse.move(r.x, r.y);
  await page.mouse.down();
  await page.mouse.move(r.x + 120, r.y + 30, { steps: 8 });
  await page.mouse.up();
  await page.mouse.wheel(0, 400);
  await sleep(300);
  const afterDrag = await page.evaluate(() => document.getElementById('bike').pose().position);
  const setByPage = await page.evaluate((c) => document.getElementById('bike').setPose({ position: [c[0], c[1] - 1, c[2] - 4], lookAt: c }) !== null, centre);
  check(gap(still, afterDrag) === 0 && setByPage, 'controls="off": a drag and the wheel leave the camera alone; setPose still moves it');
  n = (await events(page, 'connected')).length;
  await page.evaluate(() => document.getElementById('bike').removeAttribute('controls'));
  await viewerConnected(n);

  // ---- errors: a wrong token, the right one again, a scene the server lacks ----
  const errorsBefore = (await events(page, 'error')).length;
  await page.evaluate(() => document.getElementById('bike').setAttribute('token', 'wrong-token'));
  const tokenError = await waitFor('the error event of a wrong token', async () => (await events(page, 'error'))[errorsBefore], 15000);
  log(`wrong token: ${JSON.stringify(tokenError.detail)}`);
  check(tokenError.detail.name === 'ERROR_UNAUTHORIZED' && tokenError.detail.reason.length > 0 && tokenError.detail.status === 'needs-token',
    `a wrong token fires error with the server's reason (${tokenError.detail.name}: "${tokenError.detail.reason}")`);
  check(/access token/.test(await boxText(page)), `...and the element's own box says so ("${await boxText(page)}")`);
  const connects = (await events(page, 'connected')).length;
  await page.evaluate((t) => document.getElementById('bike').setAttribute('token', t), TOKEN);
  await waitFor('connected again with the right token', async () => (await events(page, 'connected')).length > connects, 30000);
  check(true, 'the right token again: connected again');
  const errorsMid = (await events(page, 'error')).length;
  await page.evaluate(() => document.getElementById('bike').setAttribute('scene', 'no-such-scene'));
  const sceneError = await waitFor('the error event of an unknown scene', async () => (await events(page, 'error'))[errorsMid], 15000);
  log(`unknown scene: ${JSON.stringify(sceneError.detail)}`);
  check(sceneError.detail.name === 'ERROR_INVALID_ARGUMENT' && /no scene 'no-such-scene'/.test(sceneError.detail.reason) &&
    sceneError.detail.status === 'no-scene' && sceneError.detail.permanent === true,
  `a scene the server lacks fires error with the server's reason ("${sceneError.detail.reason}")`);
  const shown = await page.evaluate(() => document.getElementById('viewer-status').textContent);
  check(/no scene 'no-such-scene'/.test(shown), `the site's own script shows it ("${shown}")`);
  check(/no scene named 'no-such-scene'/.test(await boxText(page)), `...and the element's box in words ("${await boxText(page)}")`);
  await run.shot(page, 'embed_error.png');
  // The host page's own words for a status replace the element's.
  await page.evaluate(() => {
    document.getElementById('bike').messages = { 'no-scene': 'This tour is not on the server today.' };
  });
  await waitFor('the host page\'s words', async () => (await boxText(page)) === 'This tour is not on the server today.', 5000)
    .then(() => check(true, 'a host page replaces the box\'s words (messages)'),
      async () => check(false, `a host page replaces the box's words ("${await boxText(page)}")`));

  // A browser without WebCodecs (an insecure page has none): the box says why.
  const bare = await context.newPage();
  await bare.addInitScript(() => {
    delete window.VideoDecoder;
  });
  await bare.goto(`${siteOrigin}/`);
  const unsupported = await waitFor('the box to say the browser cannot decode', async () => {
    const t = await boxText(bare);
    return /cannot decode/.test(t) ? t : false;
  }, 15000).catch(() => boxText(bare));
  check(/cannot decode/.test(unsupported), `no WebCodecs: the box says why ("${unsupported}")`);
  await run.shot(bare, 'embed_unsupported.png');
  await bare.close();

  // The same page on a site the server does not list: the element keeps the box the page gave it
  // (not an undefined 0x0 element) and says why it cannot stream.
  const other = await context.newPage();
  await other.addInitScript(recordEvents);
  await other.goto(`${otherOrigin}/`);
  const refusedText = await waitFor('the box to say this site may not stream', async () => {
    const t = await boxText(other).catch(() => '');
    return /may not show streams/.test(t) ? t : false;
  }, 15000).catch(() => boxText(other).catch((e) => `(no element: ${e.message})`));
  const otherBox = await other.evaluate(() => {
    const el = document.getElementById('bike');
    return { w: el.clientWidth, h: el.clientHeight, defined: !!customElements.get('catgs-viewer') };
  });
  const refusedError = (await events(other, 'error'))[0];
  check(/may not show streams from this server/.test(refusedText) && refusedText.includes(otherOrigin),
    `a site --allowed-origins lacks: the box says why ("${refusedText}")`);
  check(otherBox.defined && otherBox.w === BOX.width && otherBox.h === BOX.height && refusedError &&
    refusedError.detail.name === 'ORIGIN_REFUSED' && refusedError.detail.permanent === true,
  `...in the box the page gave it (${otherBox.w}x${otherBox.h}), with an error event (${refusedError ? refusedError.detail.name : 'none'})`);
  await run.shot(other, 'embed_refused.png');
  await other.close();

  // The server gone: the box says it is stopping (then keeps retrying), not a blank box.
  await page.evaluate((t) => {
    const el = document.getElementById('bike');
    el.messages = null;
    el.setAttribute('scene', '');
    el.setAttribute('token', t);
  }, TOKEN);
  await waitFor('connected again', async () => page.evaluate(() => document.getElementById('bike').connected), 30000);
  const exited = Promise.all(run.servers.map((p) => new Promise((r) => p.once('exit', r))));
  for (const p of run.servers) p.kill('SIGINT'); // Ctrl-C: its sessions end with ERROR_SHUTTING_DOWN
  await exited;
  const gone = await waitFor('the box to say the server is gone', async () => {
    const t = await boxText(page);
    return /server stopping|cannot reach/.test(t) ? t : false;
  }, 15000).catch(() => boxText(page));
  check(/server stopping|cannot reach/.test(gone), `the server stopped: the box says so ("${gone}")`);
  await run.shot(page, 'embed_gone.png');
  await page.close();

  // The page opened while the server is down, embedded as the README says (the loader inline): the
  // box says so and counts down, the site's own error listener hears of it, and the view streams
  // once the server is back on its address, with no reload.
  const down = await context.newPage();
  down.on('console', (m) => run.pageLog.push(`console.${m.type()}: ${m.text()}`));
  await down.addInitScript(recordEvents);
  await down.goto(`${siteOrigin}/loader`);
  const downText = await waitFor('the box to say the server cannot be reached', async () => {
    const t = await down.evaluate(() => document.getElementById('bike').innerText);
    return /cannot reach the server, retrying in \d+ s/.test(t) ? t : false;
  }, 15000).catch(() => down.evaluate(() => document.getElementById('bike').innerText));
  const downBox = await down.evaluate(() => {
    const el = document.getElementById('bike');
    return { w: el.clientWidth, h: el.clientHeight, defined: !!customElements.get('catgs-viewer'),
      site: document.getElementById('viewer-status').textContent };
  });
  const downErrors = await events(down, 'error');
  check(/cannot reach the server, retrying in \d+ s/.test(downText) && !downBox.defined && downBox.w === BOX.width &&
    downBox.h === BOX.height, `server down at load: the box the page gave (${downBox.w}x${downBox.h}) says "${downText}"`);
  check(downErrors.length > 0 && downErrors[0].detail.name === 'UNREACHABLE' && /^3D view: cannot load the viewer/.test(downBox.site),
    `...and the README's error listener heard it (${downErrors.length} events; the site says "${downBox.site}")`);
  await run.shot(down, 'embed_down.png');
  const startedAt = Date.now();
  await run.startServer(['--scene', path.join(repo, 'assets/scenes/biker.compressed.ply'), '--token-file', tokenFile,
    '--allowed-origins', siteOrigin], Number(new URL(base).port));
  await waitFor('the view to stream after the server came back', async () => (await frames(down)) > 0, 30000)
    .then(() => check(true, `the server back: the view streams ${((Date.now() - startedAt) / 1000).toFixed(1)} s after it listened, no reload`),
      () => check(false, 'the server back: the view streams without a reload'));
  check(!(await down.evaluate(() => document.getElementById('bike').innerText)).includes('cannot reach'),
    '...and the loader\'s words are gone');
  await run.shot(down, 'embed_back.png');
  await down.close();
}

// The words the <catgs-viewer> shows in its own box ('' when none).
const boxText = (page) => page.evaluate(() => document.getElementById('bike').messageText);

process.exit(await main());
