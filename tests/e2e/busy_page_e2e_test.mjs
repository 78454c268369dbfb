// A busy page is not a slow link (issue 64): the real catgs-server, and the page streaming on an
// unshaped (loopback) link while the machine and the page are busy: two CPU burner processes take
// the cores, and in the page long tasks of 100-400 ms keep its thread away at random (as a phone
// or laptop busy with other things), while the camera moves on a timer. The server's rate
// controller must never cap the stream: /metrics counts no cut and no limited session, the page's
// stats never say "cap", and frames keep coming. Screenshot: busy_page.png.
//
// usage: node busy_page_e2e_test.mjs --server BIN [--repo DIR] [--data DIR] [--out DIR] [--seconds S]
import { spawn } from 'node:child_process';
import { existsSync, mkdtempSync } from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { BrowserTestRun, browserOrSkip, sleep } from './harness.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const repo = path.resolve(args.repo || path.join(here, '../..'));
const serverBin = args.server || process.env.CATGS_SERVER;
const outDir = path.resolve(args.out || mkdtempSync(path.join(os.tmpdir(), 'catgs-busy-out-')));
const seconds = Number(args.seconds || 40);
const { chromium, chromiumPath } = browserOrSkip(here, { 'catgs-server': serverBin });
const run = new BrowserTestRun('busy-page', { serverBin, webRoot: path.join(repo, 'web_client'), outDir });
const { log, check } = run;

// flowers_sh3 from the data folder where there is one (a scene whose stream fills the cap), else
// the bundled biker.
const dataDir = path.resolve(args.data || process.env.CATGS_DATA_DIR || path.join(repo, '../shared/data'));
const flowers = path.join(dataDir, 'scenes/flowers_sh3.ply');
const scene = existsSync(flowers) ? flowers : path.join(repo, 'assets/scenes/biker.compressed.ply');

async function metric(base, name) {
  const text = await (await fetch(`${base}/metrics`)).text();
  const m = text.match(new RegExp(`^${name} ([0-9.eE+-]+)$`, 'm'));
  return m ? Number(m[1]) : NaN;
}

// In the page: the camera turns a little every 16 ms, and long tasks of 100-400 ms (busy-waiting)
// come every 50-300 ms; window.catgsBusy.stop() ends both and returns what they did.
function startBusyPage(page) {
  return page.evaluate(() => {
    const { position: p, orientation: q, fovDeg: f } = window.catgs.pose();
    const busy = (window.catgsBusy = { tasks: 0, busyMs: 0, poses: 0, stopped: false });
    let i = 0;
    const move = setInterval(() => {
      const d = 0.05 * Math.sin(++i * 0.02);
      if (window.catgs.setPose([p[0] + d, p[1], p[2] + d], q, f) !== null) busy.poses++;
    }, 16);
    const longTask = () => {
      if (busy.stopped) return;
      const ms = 100 + Math.random() * 300;
      const t0 = performance.now();
      while (performance.now() - t0 < ms);
      busy.tasks++;
      busy.busyMs += ms;
      setTimeout(longTask, 50 + Math.random() * 250);
    };
    setTimeout(longTask, 100);
    busy.stop = () => {
      busy.stopped = true;
      clearInterval(move);
      return { tasks: busy.tasks, busyMs: busy.busyMs, poses: busy.poses };
    };
  });
}

process.exit(await run.main(chromium, chromiumPath, { viewport: { width: 480, height: 360 } }, async (context) => {
  const base = await run.startServer(['--scene', scene]);
  log(`scene ${path.basename(scene)}; ${seconds} s with two CPU burners and long tasks in the page`);
  const page = await run.openPage(context, `${base}/?stats=1`);
  const burners = [0, 1].map(() => spawn(process.execPath, ['-e', 'for(;;){}'], { stdio: 'ignore' }));
  let caps = 0;
  const framesBefore = await page.evaluate(() => window.catgs.framesDecoded);
  try {
    await startBusyPage(page);
    const end = Date.now() + seconds * 1000;
    while (Date.now() < end) {
      await sleep(2000);
      const stats = await page.evaluate(() => document.getElementById('stats').textContent);
      if (/\bcap \d/.test(stats)) caps++;
    }
  } finally {
    burners.forEach((b) => b.kill('SIGKILL'));
  }
  const did = await page.evaluate(() => window.catgsBusy.stop());
  const frames = (await page.evaluate(() => window.catgs.framesDecoded)) - framesBefore;
  const cuts = await metric(base, 'catgs_link_rate_decreases_total');
  const limited = await metric(base, 'catgs_sessions_link_limited');
  const receipts = await metric(base, 'catgs_frame_receipts_total');
  const byCause = await Promise.all(['send_delay', 'receipts', 'round_trip'].map((c) =>
    metric(base, `catgs_link_rate_cuts_total\\{cause="${c}"\\}`)));
  await run.shot(page, 'busy_page.png');
  const stats = await page.evaluate(() => document.getElementById('stats').textContent);
  log(`page: ${did.tasks} long tasks (${(did.busyMs / 1000).toFixed(1)} s busy), ${did.poses} poses, ${frames} frames; ` +
    `server: ${cuts} cuts (send delay / receipts / round trip: ${byCause.join(' / ')}), ${limited} sessions limited, ` +
    `${receipts} receipts read; stats:\n${stats}`);
  check(did.tasks >= seconds, `the page was busy: ${did.tasks} long tasks, ${(did.busyMs / 1000).toFixed(1)} s of ${seconds}`);
  check(frames >= 5, `frames kept coming (${frames})`);
  check(cuts === 0, `the rate controller never cut a busy page's stream on an unshaped link (${cuts} cuts)`);
  check(limited === 0, `no session link-limited at the end (${limited})`);
  check(caps === 0 && !/\bcap \d/.test(stats), `the page's stats never said "cap" (${caps} of the 2 s samples)`);
}));
