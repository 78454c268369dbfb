// Benchmark (not a test): what a running video export does to a live session's latency. A real
// catgs-server (the bundled biker) streams to catgs-loadgen (one session, its orbit trace, frames
// decoded) twice for the same time: once while a page (an author, headless Chromium) sits idle,
// once while that page's Export video renders a path (the export's frames are background jobs on
// the render lanes, session/session_export.cpp). Prints a table and writes the JSON (both
// loadgen reports and the export's frames in each phase).
//
// usage: node tests/e2e/export_load_bench.mjs --server B/catgs-server --loadgen B/catgs-loadgen
//          [--renderer cpu|cuda] [--size 480x270] [--export-size 640x360] [--export-fps 30]
//          [--seconds 15] [--out DIR]
// On the GPU host it needs Chromium and node, which it lacks: run it on the build machine (CPU
// core) or put a browser there.
import { execFileSync, spawn } from 'node:child_process';
import { mkdirSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { CHROMIUM_ARGS, freePort, sleep, stopServers, waitFor } from './harness.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const repo = path.resolve(here, '../..');
const seconds = Number(args.seconds || 15);
const size = args.size || '480x270';
const exportSize = args['export-size'] || '640x360';
const exportFps = Number(args['export-fps'] || 30);
const outDir = path.resolve(args.out || mkdtempSync(path.join(os.tmpdir(), 'catgs-export-bench-')));
mkdirSync(outDir, { recursive: true });
const require = createRequire(import.meta.url);
const { chromium } = require('playwright-core');

const tmp = mkdtempSync(path.join(os.tmpdir(), 'catgs-export-bench-'));
writeFileSync(path.join(tmp, 'tokens'), 'author A1\n');
const port = await freePort();
const server = spawn(args.server, ['--port', String(port), '--renderer', args.renderer || 'cpu', '--token-file',
  path.join(tmp, 'tokens'), '--export-dir', path.join(tmp, 'exports'), '--web-root', path.join(repo, 'web_client')],
{ stdio: ['ignore', 'ignore', 'inherit'] });
const base = `http://127.0.0.1:${port}`;
let context = null;
const report = { size, export_size: exportSize, export_fps: exportFps, seconds, phases: {} };
try {
  await waitFor('the server', () => fetch(`${base}/readyz`).then((r) => r.ok, () => false), 60000, 200);
  context = await chromium.launchPersistentContext(path.join(tmp, 'chromium'), {
    executablePath: process.env.CATGS_CHROMIUM || '/usr/bin/chromium', headless: true, args: CHROMIUM_ARGS,
    viewport: { width: 320, height: 180 }, deviceScaleFactor: 1,
  });
  const page = await context.newPage();
  await page.goto(`${base}/?token=A1`);
  await page.waitForFunction(() => window.catgs && window.catgs.framesDecoded > 0, null, { timeout: 60000 });
  // A path long enough to outlast the loadgen run: the first view, then 3 cm to the side, 60 s on.
  await page.evaluate(() => {
    const p = window.catgs.pose();
    const v = window.catgs.viewport;
    const line = (t, x) => [t, x, p.position[1], p.position[2], ...p.orientation, 500, 500, v.width / 2, v.height / 2, v.width, v.height].join(' ');
    window.catgs.importText('bench.trace', `catgs-trace 1\n${line(0, p.position[0])}\n${line(60, p.position[0] + 0.03)}\n`);
  });
  const loadgen = (name) => {
    const json = path.join(outDir, `loadgen_${name}.json`);
    execFileSync(args.loadgen, ['--port', String(port), '--sessions', '1', '--size', size, '--seconds', String(seconds),
      '--decode', '1', '--token', 'A1', '--json', json], { stdio: ['ignore', 'ignore', 'inherit'] });
    return JSON.parse(readFileSync(json, 'utf8'));
  };
  const framesDone = () => page.evaluate(() => (window.catgs.videoExport.progress || {}).frames_done || 0);
  report.phases.idle = { loadgen: loadgen('idle'), export_frames: 0 };
  await page.evaluate(([s, f]) => window.catgs.exportVideo({ size: s, fps: f }), [exportSize, exportFps]);
  await waitFor('the export to start', async () => (await framesDone()) > 0, 60000);
  const before = await framesDone();
  const during = loadgen('export');
  report.phases.export = { loadgen: during, export_frames: (await framesDone()) - before };
  await page.evaluate(() => window.catgs.cancelExport());
  await sleep(500);
} finally {
  if (context) await context.close().catch(() => {});
  await stopServers([server]);
  rmSync(tmp, { recursive: true, force: true });
}
writeFileSync(path.join(outDir, 'export_load_bench.json'), JSON.stringify(report, null, 1) + '\n');
console.log(`live session ${size} (catgs-loadgen, ${seconds} s) with an export of ${exportSize} at ${exportFps} fps`);
console.log('| phase | fps | latency p50 ms | p95 ms | p99 ms | export frames rendered |');
console.log('|---|---|---|---|---|---|');
for (const [name, p] of Object.entries(report.phases)) {
  const s = p.loadgen.run.sessions[0];
  console.log(`| ${name} | ${s.fps.toFixed(1)} | ${s.latency.p50_ms.toFixed(1)} | ${s.latency.p95_ms.toFixed(1)} | ` +
    `${s.latency.p99_ms.toFixed(1)} | ${p.export_frames} |`);
}
console.log(`JSON: ${path.join(outDir, 'export_load_bench.json')}`);
