// The stream's size: the canvas in device pixels, capped, even, within the protocol's range.
// Pure (no DOM), so node unit-tests it.

export const DEFAULT_MAX = { long: 1920, short: 1080 };

// ?max=WxH -> { long, short } sides of the cap (orientation-free: a portrait phone gets
// 1080x1920 at most). Bad or missing input gives the default.
export function parseMaxSize(s) {
  const m = /^(\d+)x(\d+)$/.exec(String(s || '').trim());
  if (!m) return { ...DEFAULT_MAX };
  const a = Math.min(Math.max(Number(m[1]), 16), 4096);
  const b = Math.min(Math.max(Number(m[2]), 16), 4096);
  return { long: Math.max(a, b), short: Math.min(a, b) };
}

// width x height device pixels scaled down uniformly (aspect kept) until the long side fits
// max.long and the short side max.short; then even (4:2:0 chroma) and within 16..4096.
export function capViewport(width, height, max = DEFAULT_MAX) {
  const long = Math.max(width, height);
  const short = Math.min(width, height);
  const s = Math.min(1, max.long / Math.max(long, 1), max.short / Math.max(short, 1));
  // The epsilon keeps 2532 * (1920 / 2532) at 1920 rather than 1919.9999 -> 1918.
  const even = (v) => Math.min(4096, Math.max(16, Math.floor((v * s + 1e-6) / 2) * 2));
  return { width: even(width), height: even(height) };
}
