// End-to-end test of issue 38's "Export video": the real catgs-server (CPU renderer) and headless
// Chromium, driven through the Paths panel and the page's test hook (window.catgs), with
// screenshots saved for a look.
//
// One server (the bundled biker, a token file with an author and a viewer, caps lowered to
// 640x360 and 20 s, its export folder holding a stale file from "an earlier run"):
//  - start-up deleted the stale export file;
//  - the author records a short path (the hook moves the camera while the recorder runs), picks
//    160x90 at 10 fps and clicks "Export video": the progress bar shows, the file arrives as a
//    download link, and the downloaded MP4, read by FFmpeg's demuxer and decoder
//    (catgs-video-probe), has the frame count the path's span gives at 10 fps, the size and the
//    duration; the server's temporary file is gone;
//  - a longer export at 640x360 shows the bar part way (screenshot), a second request meanwhile
//    is refused ("still running"), Cancel stops it and its file goes;
//  - an export over a cap (1280x720 past --export-max-size 640x360) shows the clear error, naming
//    the flag, in the page, and the live view keeps streaming;
//  - a viewer's export is refused (an author token is needed) and its session streams on.
//
// usage: node export_e2e_test.mjs --server PATH/catgs-server --probe PATH/catgs-video-probe
//        [--repo ROOT] [--out DIR]
// Exit codes: 0 pass, 1 fail, 77 skipped (no chromium / npm deps / binaries).
import { execFileSync } from 'node:child_process';
import { mkdirSync, mkdtempSync, readdirSync, writeFileSync } from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { BrowserTestRun, browserOrSkip, sleep, waitFor } from './harness.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const repo = path.resolve(args.repo || path.join(here, '../..'));
const serverBin = args.server || process.env.CATGS_SERVER;
const probeBin = args.probe;
const outDir = path.resolve(args.out || mkdtempSync(path.join(os.tmpdir(), 'catgs-export-out-')));
const VIEW = { width: 480, height: 360 };
const { chromium, chromiumPath } = browserOrSkip(here, { 'catgs-server': serverBin, 'catgs-video-probe': probeBin });
const run = new BrowserTestRun('export', { serverBin, webRoot: path.join(repo, 'web_client'), outDir });
const { log, check } = run;
let context = null;
const openPage = (url) => run.openPage(context, url);
const hook = (page, fn, arg) => page.evaluate(fn, arg);
const shot = (page, name) => run.shot(page, name);
const exportFiles = (dir) => readdirSync(dir).filter((f) => f.startsWith('catgs-export-'));

// Records a path: the camera turns a little around its start, one step every 150 ms.
async function recordPath(page, steps) {
  const start = await hook(page, () => window.catgs.pose());
  await hook(page, () => window.catgs.toggleRecording());
  for (let k = 1; k <= steps; k++) {
    await sleep(150);
    await hook(page, ([p, k]) => {
      const a = 0.02 * k; // radians about the camera's own y axis
      const q = p.orientation;
      const r = [Math.cos(a / 2), 0, Math.sin(a / 2), 0];
      const mul = (x, y) => [
        x[0] * y[0] - x[1] * y[1] - x[2] * y[2] - x[3] * y[3],
        x[0] * y[1] + x[1] * y[0] + x[2] * y[3] - x[3] * y[2],
        x[0] * y[2] - x[1] * y[3] + x[2] * y[0] + x[3] * y[1],
        x[0] * y[3] + x[1] * y[2] - x[2] * y[1] + x[3] * y[0],
      ];
      window.catgs.setPose(p.position, mul(q, r), p.fovDeg);
    }, [start, k]);
  }
  await sleep(150);
  await hook(page, () => window.catgs.toggleRecording());
  return hook(page, () => window.catgs.recording);
}

// Picks a size in the panel's menu (adding it when the menu lacks it: the test's small sizes).
async function pickSize(page, size, fps) {
  if (!(await page.isVisible('#paths'))) await page.click('#btn-paths');
  await page.evaluate(([size, fps]) => {
    const s = document.getElementById('export-size');
    if (![...s.options].some((o) => o.value === size)) s.add(new Option(size, size));
    s.value = size;
    const f = document.getElementById('export-fps');
    if (![...f.options].some((o) => o.value === String(fps))) f.add(new Option(`${fps} fps`, String(fps)));
    f.value = String(fps);
  }, [size, fps]);
}

// Clicks Export video; resolves with the server's refusal.
async function exportRefusal(page) {
  await page.click('#btn-export-video');
  return waitFor('the refusal', async () => {
    const s = await hook(page, () => window.catgs.videoExport);
    return s.progress && s.progress.error;
  }, 10000);
}

async function streamsOn(page, what) {
  const before = await hook(page, () => window.catgs.framesDecoded);
  const p = await hook(page, () => window.catgs.pose());
  await hook(page, (p) => window.catgs.setPose(p.position, p.orientation, p.fovDeg * 0.97), p);
  await waitFor(`a frame after ${what}`, async () => (await hook(page, () => window.catgs.framesDecoded)) > before, 20000);
  check(await hook(page, () => window.catgs.connected), `the session streams on after ${what}`);
}

async function scenarios(tmp) {
  const exportDir = path.join(tmp, 'exports');
  mkdirSync(exportDir);
  writeFileSync(path.join(exportDir, 'catgs-export-0badc0de.mp4'), 'left by a killed server');
  writeFileSync(path.join(tmp, 'tokens'), 'author A1\nviewer V1\nadmin X1\n');
  const base = await run.startServer(['--token-file', path.join(tmp, 'tokens'), '--export-dir', exportDir,
    '--export-max-size', '640x360', '--export-max-seconds', '20']);

  // ---- the author: record, export, download ----
  const page = await openPage(`${base}/?token=A1`);
  // (the probes answer while the scene loads; the sessions, and the export folder, come after)
  check(exportFiles(exportDir).length === 0, 'start-up deleted the stale export file');
  const rec = await recordPath(page, 10);
  const span = rec[rec.length - 1].t - rec[0].t;
  check(rec.length >= 5 && span > 1, `a path recorded (${rec.length} poses, ${span.toFixed(2)} s)`);
  const fps = 10;
  const frames = Math.floor(span * fps + 1e-6) + 1;
  await pickSize(page, '160x90', fps);
  await page.click('#btn-export-video');
  await waitFor('the progress bar', () => page.isVisible('#export-row'), 5000);
  const link = await waitFor('the download link', async () => (await page.isVisible('#export-download')) && true, 60000)
    .catch(async (e) => {
      await shot(page, 'export_failed.png');
      throw new Error(`${e.message}: ${JSON.stringify(await hook(page, () => window.catgs.videoExport))}`);
    });
  check(link, 'the file arrived: the panel offers the download');
  const state = await hook(page, () => window.catgs.videoExport);
  log(`export state: ${JSON.stringify(state)}`);
  check(state.progress && state.progress.done && state.progress.frames_total === frames,
    `the server rendered ${state.progress && state.progress.frames_total} frames, the path's span at ${fps} fps gives ${frames}`);
  await shot(page, 'export_ready.png');
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#export-download')]);
  const file = path.join(outDir, 'export.mp4');
  await download.saveAs(file);
  const probe = JSON.parse(execFileSync(probeBin, [file], { encoding: 'utf8' }));
  log(`FFmpeg reads the download: ${JSON.stringify(probe)}`);
  check(probe.codec === 'h264' && probe.width === 160 && probe.height === 90, 'the download is H.264, 160x90');
  check(probe.frames === frames, `the download has ${probe.frames} frames (${frames} expected)`);
  check(Math.abs(probe.fps - fps) < 1e-6 && Math.abs(probe.duration_s - frames / fps) < 1e-6,
    `the download lasts ${probe.duration_s} s at ${probe.fps} fps (${frames / fps} s expected)`);
  await waitFor('the server to delete its copy', () => exportFiles(exportDir).length === 0, 5000)
    .then(() => check(true, 'the server deleted its temporary file after sending it'),
      () => check(false, `the server kept ${exportFiles(exportDir)}`));

  // ---- a longer export: the bar part way, a second request refused, Cancel ----
  await pickSize(page, '640x360', 30);
  await page.click('#btn-export-video');
  const mid = await waitFor('progress part way', async () => {
    const s = await hook(page, () => window.catgs.videoExport);
    return s.progress && s.progress.frames_done > 0 && !s.progress.done ? s : null;
  }, 60000, 50);
  await shot(page, 'export_progress.png');
  const bar = await page.$eval('#export-progress', (el) => el.value);
  const text = await page.textContent('#export-status');
  check(bar > 0 && bar < 1 && /rendering \d+\/\d+ frames, \d+:\d\d left/.test(text),
    `the bar shows the progress with the time left ("${text}", ${bar.toFixed(2)})`);
  check(exportFiles(exportDir).length === 1, 'the export renders into one temporary file');
  // The panel will not start a second one; a request sent beside it anyway is refused by the server.
  check((await hook(page, () => window.catgs.exportVideo({ size: '160x90', fps: 10 }))) === null,
    'the panel starts no second export while one runs');
  const other = await hook(page, () => window.catgs.exportVideo({ size: '160x90', fps: 10, alongside: true }));
  const refused = await waitFor('the server\'s refusal of the second', async () => {
    const s = await hook(page, () => window.catgs.videoExport);
    return s.others[other] && s.others[other].error;
  }, 10000);
  check(/still running/.test(refused), `a second export while one runs is refused: "${refused}"`);
  check((await hook(page, () => window.catgs.videoExport)).running === mid.running, 'the first export goes on');
  await page.click('#btn-export-cancel');
  await waitFor('the export to stop', () => exportFiles(exportDir).length === 0, 10000)
    .then(() => check(true, 'Cancel stopped the export and its file was deleted'),
      () => check(false, `a cancelled export left ${exportFiles(exportDir)}`));
  const after = await waitFor('the page to hear of the cancel', async () => {
    const s = await hook(page, () => window.catgs.videoExport);
    return s.progress && s.progress.cancelled ? s : null;
  }, 10000);
  check(after.running === null && after.status === 'export cancelled', `the panel says so ("${after.status}")`);
  await streamsOn(page, 'the export and its cancel');

  // ---- over a cap: a clear error in the page, the view streams on ----
  await pickSize(page, '1280x720', 30);
  const err = await exportRefusal(page);
  const shown = await page.textContent('#export-status');
  check(/1280x720 is over the server's --export-max-size 640x360/.test(shown),
    `the page shows the cap and its flag: "${shown}"`);
  await shot(page, 'export_over_cap.png');
  await streamsOn(page, `the refused export (${err})`);
  await page.close();

  // ---- a viewer may not export ----
  // The page hides Export video from a viewer (Welcome.can_export); a request sent anyway (through
  // the hook, as a hand-made client would) is refused by the server.
  const viewer = await openPage(`${base}/?token=V1`);
  await recordPath(viewer, 3);
  if (!(await viewer.isVisible('#paths'))) await viewer.click('#btn-paths');
  check(!(await viewer.isVisible('#btn-export-video')) && !(await hook(viewer, () => window.catgs.welcome.can_export)),
    'a viewer\'s page shows no Export video (Welcome.can_export is false)');
  await shot(viewer, 'export_viewer_paths.png');
  await hook(viewer, () => window.catgs.exportVideo({ size: '160x90', fps: 10 }));
  const no = await waitFor('the refusal', async () => {
    const s = await hook(viewer, () => window.catgs.videoExport);
    return s.progress && s.progress.error;
  }, 10000);
  check(/needs an author or admin token/.test(no), `a viewer's export sent anyway is refused: "${no}"`);
  await streamsOn(viewer, 'the viewer\'s refused export');
  await viewer.close();

  // ---- /metrics counts what happened above: one export sent, one cancelled, three refused ----
  const metrics = await fetch(`${base}/metrics`, { headers: { Authorization: 'Bearer X1' } }).then((r) => r.text());
  const value = (series) => Number((metrics.match(new RegExp(`^${series.replace(/[{}"]/g, '\\$&')} (\\S+)$`, 'm')) || [])[1]);
  const counts = ['sent', 'cancelled', 'failed', 'refused'].map((r) => value(`catgs_exports_total{result="${r}"}`));
  check(counts.join() === '1,1,0,3' && value('catgs_exports_running') === 0,
    `/metrics counts the exports (sent, cancelled, failed, refused: ${counts.join(', ')}; running ${value('catgs_exports_running')})`);
  check(value('catgs_export_frames_total') >= frames,
    `/metrics counts the export frames (${value('catgs_export_frames_total')}, at least the ${frames} of the sent one)`);
}

process.exit(await run.main(chromium, chromiumPath, { viewport: VIEW, acceptDownloads: true }, async (ctx, tmp) => {
  context = ctx;
  await scenarios(tmp);
}));
