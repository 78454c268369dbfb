// What the browser tests share (e2e_test.mjs, notes_e2e_test.mjs, export_e2e_test.mjs): ports,
// polling, Chromium's flags, stopping the servers they started, and a test run against real
// servers (its checks, servers, pages and screenshots).
import { spawn } from 'node:child_process';
import { existsSync, mkdirSync, mkdtempSync, rmSync } from 'node:fs';
import { createRequire } from 'node:module';
import net from 'node:net';
import os from 'node:os';
import path from 'node:path';

// Flags that work for Debian's chromium as root (checked on these machines); playwright-core's
// launchPersistentContext takes the profile folder itself.
export const CHROMIUM_ARGS = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync'];

export function freePort() {
  return new Promise((resolve, reject) => {
    const s = net.createServer();
    s.once('error', reject);
    s.listen(0, '127.0.0.1', () => {
      const { port } = s.address();
      s.close(() => resolve(port));
    });
  });
}

export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// Polls fn() until it returns something truthy (returned), or throws after timeoutMs.
export async function waitFor(what, fn, timeoutMs, intervalMs = 100) {
  const end = Date.now() + timeoutMs;
  let last;
  for (;;) {
    last = await fn();
    if (last) return last;
    if (Date.now() > end) throw new Error(`timed out after ${timeoutMs} ms waiting for ${what}`);
    await sleep(intervalMs);
  }
}

// SIGTERM to each server still running (it drains), SIGKILL after 5 s; resolves when all exited.
export async function stopServers(procs) {
  for (const proc of procs) {
    if (proc.exitCode !== null || proc.signalCode !== null) continue;
    proc.kill('SIGTERM');
    const killer = setTimeout(() => proc.kill('SIGKILL'), 5000);
    await new Promise((r) => proc.once('exit', r));
    clearTimeout(killer);
  }
}

// ---- a browser test against real servers (notes_e2e_test.mjs, export_e2e_test.mjs) ----

// Exits with 77 (ctest's SKIP) and the reason when Chromium, the npm packages or one of
// `binaries` ({ name: path }) is missing; else returns playwright-core's chromium.
export function browserOrSkip(e2eDir, binaries) {
  const chromiumPath = process.env.CATGS_CHROMIUM || '/usr/bin/chromium';
  const skip = (why) => {
    console.log(`SKIP: ${why}`);
    process.exit(77);
  };
  if (!existsSync(chromiumPath)) skip(`${chromiumPath} is missing (apt-get install chromium)`);
  if (!existsSync(path.join(e2eDir, 'node_modules/playwright-core'))) skip('tests/e2e/node_modules is missing: run scripts/setup_web.sh');
  for (const [name, bin] of Object.entries(binaries)) {
    if (!bin || !existsSync(bin)) skip(`${name} binary not given or missing (${bin || 'none'})`);
  }
  const require = createRequire(path.join(e2eDir, 'harness.mjs'));
  return { chromium: require('playwright-core').chromium, chromiumPath };
}

// One test's run: its checks, the catgs-servers it starts (CPU renderer, their output kept), the
// pages it opens (their console kept) and its screenshots.
export class BrowserTestRun {
  constructor(name, { serverBin, webRoot, outDir }) {
    this.name = name;
    this.serverBin = serverBin;
    this.webRoot = webRoot;
    this.outDir = outDir;
    this.failures = [];
    this.servers = [];
    this.serverLog = '';
    this.pageLog = [];
    this.log = (...m) => console.log(`[${name}]`, ...m);
    this.check = (ok, what) => {
      this.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
      if (!ok) this.failures.push(what);
    };
  }

  // Starts catgs-server with `serverArgs` on `port` (a free one when not given); resolves with
  // its base URL once it answers HTTP.
  async startServer(serverArgs, port = 0) {
    port = port || (await freePort());
    const all = [...serverArgs, '--port', String(port), '--renderer', 'cpu', '--web-root', this.webRoot,
      '--cache-dir', path.join(os.tmpdir(), 'catgs-e2e-cache')];
    this.log(`starting catgs-server ${all.join(' ')}`);
    const proc = spawn(this.serverBin, all, { stdio: ['ignore', 'pipe', 'pipe'] });
    this.servers.push(proc);
    proc.stdout.on('data', (d) => (this.serverLog += d));
    proc.stderr.on('data', (d) => (this.serverLog += d));
    const base = `http://127.0.0.1:${port}`;
    await waitFor('the server to answer HTTP', async () => {
      if (proc.exitCode !== null) throw new Error(`catgs-server exited with ${proc.exitCode}`);
      return fetch(`${base}/`).then((r) => r.ok, () => false);
    }, 60000, 200);
    return base;
  }

  // Opens `url` in `context`; resolves once the page streams (its first frame decoded).
  async openPage(context, url) {
    const page = await context.newPage();
    page.on('console', (m) => this.pageLog.push(`console.${m.type()}: ${m.text()}`));
    page.on('pageerror', (e) => this.pageLog.push(`pageerror: ${e.message}`));
    await page.goto(url);
    await page.waitForFunction(() => window.catgs && window.catgs.connected && window.catgs.framesDecoded > 0, null, { timeout: 60000 });
    return page;
  }

  async shot(page, file) {
    const f = path.join(this.outDir, file);
    await page.screenshot({ path: f });
    this.log(`screenshot ${f}`);
  }

  // Runs body(context, tmp) in a fresh headless Chromium (contextOptions: viewport, ...) with a
  // temporary folder; then stops the servers, prints the summary (and, on a failure, the logs'
  // tails) and resolves with the exit code.
  async main(chromium, chromiumPath, contextOptions, body) {
    let code = 0;
    let context = null;
    const profileDir = mkdtempSync(path.join(os.tmpdir(), `catgs-${this.name}-chromium-`));
    const tmp = mkdtempSync(path.join(os.tmpdir(), `catgs-${this.name}-`));
    try {
      mkdirSync(this.outDir, { recursive: true });
      context = await chromium.launchPersistentContext(profileDir, {
        executablePath: chromiumPath, headless: true, args: CHROMIUM_ARGS, deviceScaleFactor: 1, ...contextOptions,
      });
      await body(context, tmp);
    } catch (e) {
      console.error(`[${this.name}] FAIL: ${e.stack || e}`);
      code = 1;
    } finally {
      if (context) await context.close().catch(() => {});
      code = await this.finish(code);
      rmSync(profileDir, { recursive: true, force: true });
      rmSync(tmp, { recursive: true, force: true });
    }
    return code;
  }

  // Stops the servers; with a failure, prints the logs' tails; prints the summary; the exit code.
  async finish(code) {
    await stopServers(this.servers);
    if (code === 0 && this.failures.length) code = 1;
    if (code !== 0) {
      console.error(`[${this.name}] page log:\n` + this.pageLog.slice(-60).join('\n'));
      console.error(`[${this.name}] server log (tail):\n` + this.serverLog.slice(-4000));
    }
    console.log(code === 0 ? '1 passed, 0 failed' : `0 passed, 1 failed (${this.failures.length} checks)`);
    return code;
  }
}
