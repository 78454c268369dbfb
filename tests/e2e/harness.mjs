// What the browser tests share (e2e_test.mjs, notes_e2e_test.mjs): ports, polling, Chromium's
// flags and stopping the servers they started.
import net from 'node:net';

// Flags that work for Debian's chromium as root (TOOLCHAIN.md); playwright-core's
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
