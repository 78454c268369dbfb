// Benchmark (not a test): how long headless Chromium's WebCodecs takes to decode the streams
// catgs-encode-bench wrote with --dump-dir (rowN.h264 / rowN.obu and rowN.json: the codec, the
// size and each access unit's bytes). Each stream is decoded as the page decodes the server's
// (web_client/viewer/decoder.js: configured from the first key frame's SPS or sequence header by the
// page's own h264.js / av1.js, optimizeForLatency, no description), one access unit at a time:
// a unit's time is from decode() to its VideoFrame's output, the delay a frame waits before it
// can be drawn. Prints a table and writes JSON (per row: p50 / p95 / max ms, frames decoded).
//
// usage: node tests/e2e/decode_bench.mjs --dir DUMP_DIR [--out decode.json] [--repeat 2]
// (Chromium: CATGS_CHROMIUM or /usr/bin/chromium, software decoding: --disable-gpu.)
import { readFileSync, readdirSync, mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { CHROMIUM_ARGS, browserOrSkip } from './harness.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
if (!args.dir) {
  console.error('usage: node tests/e2e/decode_bench.mjs --dir DUMP_DIR [--out decode.json] [--repeat 2]');
  process.exit(2);
}
const repeat = Number(args.repeat || 2);
const webRoot = path.resolve(here, '../../web_client');
const { chromium, chromiumPath } = browserOrSkip(here, {});

// The page's modules over http://127.0.0.1 (a secure context: WebCodecs needs one).
const server = http.createServer((req, res) => {
  const name = path.basename(new URL(req.url, 'http://x').pathname) || 'blank';
  if (name === 'blank') {
    res.writeHead(200, { 'Content-Type': 'text/html' });
    res.end('<!doctype html><title>decode bench</title>');
    return;
  }
  try {
    const body = readFileSync(path.join(webRoot, name));
    res.writeHead(200, { 'Content-Type': 'text/javascript' });
    res.end(body);
  } catch (_) {
    res.writeHead(404);
    res.end();
  }
});
await new Promise((r) => server.listen(0, '127.0.0.1', r));
const base = `http://127.0.0.1:${server.address().port}`;

const percentile = (v, p) => {
  const s = [...v].sort((a, b) => a - b);
  return s.length ? s[Math.min(s.length - 1, Math.floor(p * (s.length - 1) + 0.5))] : NaN;
};

const profile = mkdtempSync(path.join(os.tmpdir(), 'catgs-decode-bench-'));
const context = await chromium.launchPersistentContext(profile, { executablePath: chromiumPath, headless: true, args: CHROMIUM_ARGS });
const rows = [];
try {
  const page = context.pages()[0] || (await context.newPage());
  await page.goto(`${base}/blank`);
  const streams = readdirSync(args.dir).filter((n) => /^row\d+\.json$/.test(n))
    .sort((a, b) => Number(a.match(/\d+/)[0]) - Number(b.match(/\d+/)[0]));
  for (const name of streams) {
    const meta = JSON.parse(readFileSync(path.join(args.dir, name), 'utf8'));
    const bits = readFileSync(path.join(args.dir, name.replace('.json', meta.codec === 'av1' ? '.obu' : '.h264')));
    const units = [];
    let at = 0;
    for (const n of meta.sizes) {
      units.push(bits.subarray(at, at + n).toString('base64'));
      at += n;
    }
    const result = await page.evaluate(async ([codec, units, fps, repeat]) => {
      const inspect = codec === 'av1'
        ? (await import('/viewer/av1.js')).inspectTemporalUnit
        : (await import('/viewer/h264.js')).inspectAccessUnit;
      const bytes = units.map((u) => Uint8Array.from(atob(u), (c) => c.charCodeAt(0)));
      const codecString = inspect(bytes[0]).codec;
      const times = [];
      for (let r = 0; r < repeat; r++) {
        let resolveOutput = null;
        let rejectOutput = null;
        const decoder = new VideoDecoder({
          output: (frame) => {
            frame.close();
            if (resolveOutput) resolveOutput();
          },
          error: (e) => { if (rejectOutput) rejectOutput(e); }, // fails the run rather than waiting forever
        });
        decoder.configure({ codec: codecString, optimizeForLatency: true });
        for (let k = 0; k < bytes.length; k++) {
          const out = new Promise((resolve, reject) => { resolveOutput = resolve; rejectOutput = reject; });
          const t0 = performance.now();
          decoder.decode(new EncodedVideoChunk({ type: k === 0 ? 'key' : 'delta', timestamp: Math.round(k * 1e6 / fps), data: bytes[k] }));
          await out;
          if (r === repeat - 1) times.push(performance.now() - t0);
        }
        decoder.close();
      }
      return { codecString, times };
    }, [meta.codec, units, meta.fps, repeat]);
    const t = result.times;
    const row = {
      label: meta.label, codec: meta.codec, codec_string: result.codecString, width: meta.width, height: meta.height,
      frames: t.length, decode_ms: { p50: percentile(t, 0.5), p95: percentile(t, 0.95), max: Math.max(...t) },
    };
    rows.push(row);
    console.error(`done: ${meta.label}`);
  }
} finally {
  await context.close();
  server.close();
  rmSync(profile, { recursive: true, force: true });
}
console.log(`Chromium WebCodecs decode, one access unit at a time (decode() to output), ${chromiumPath}`);
console.log('| stream | codec | size | frames | decode ms p50 / p95 / max |\n|---|---|---|---|---|');
for (const r of rows) {
  console.log(`| ${r.label} | ${r.codec_string} | ${r.width}x${r.height} | ${r.frames} | ` +
    `${r.decode_ms.p50.toFixed(2)} / ${r.decode_ms.p95.toFixed(2)} / ${r.decode_ms.max.toFixed(2)} |`);
}
if (args.out) writeFileSync(args.out, JSON.stringify({ chromium: chromiumPath, rows }, null, 1) + '\n');
