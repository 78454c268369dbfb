// A stand-in for catgs-server in browser tests of the page's own behaviour (errors, reconnects,
// decoder recovery, resize), which the real server cannot be made to show on demand. It serves
// web_client/ over HTTP and speaks the protocol over a minimal RFC 6455 WebSocket, answering each
// Pose with the next access unit of a canned H.264 fixture (fixtures/stream_160x120.bin).
//
// The WebSocket path picks the scenario: /ws normal; /ws-error sends Error(TOO_SLOW) after 5
// frames and closes; /ws-garbage sends an undecodable "key frame" as the 4th frame; /ws-token
// wants Hello.token "sesame" (else Error(UNAUTHORIZED)); /ws-full refuses the first two Hellos
// with Error(SERVER_FULL, retry_after_ms 2500); /ws-restart sends Error(SHUTTING_DOWN,
// retry_after_ms 1200, "server restarting": a server that knows it comes back) after 5 frames,
// /ws-stop the same with catgs-server's own reason on SIGTERM or SIGINT ("server shutting down",
// which does not say whether it comes back); /ws-noframes welcomes but never sends a frame; /ws-hold
// answers the first Pose only (the page keeps showing that frame, re-projected); /ws-hold-depth the
// same with a depth grid on the frame (its left part 2 units away, its right part 20, deflated as
// catgs-server sends it: proto/depth_grid_coding.h); /ws-drain sends
// Stats.drain_ms_left 2600 (a draining server) right after Welcome and streams on. GET /scenes
// lists three scenes, one with unknown counts (the page's picker); a Hello naming another scene is
// refused as catgs-server refuses it (INVALID_ARGUMENT "no scene 'X' on this server (it has:
// ...)"). A DepthRequest is answered with a hit 5 units ahead (the Notes panel's clicks). Every
// session gets Stats once a second (frames_sent cumulative, means 0 when nothing was rendered, as
// the server does). Under /noproto/ the page is served but .proto answers 415 (as libwebsockets
// does without a MIME type).
import crypto from 'node:crypto';
import fs from 'node:fs';
import http from 'node:http';
import { createRequire } from 'node:module';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import zlib from 'node:zlib';

const here = path.dirname(fileURLToPath(import.meta.url));
const require = createRequire(import.meta.url);
const WS_GUID = '258EAFA5-E914-47DA-95CA-C5AB0DC85B11';
const MIME = { '.html': 'text/html', '.js': 'text/javascript', '.css': 'text/css', '.json': 'application/json', '.proto': 'text/plain' };

// Three scenes, as a server with three --scene files lists them (the WebSocket serves 'mock');
// 'city' is not loaded yet and its format cannot be peeked, so its counts are null.
const SCENES = [
  { name: 'mock', gaussians: 152746, sh_degree: 0, bounds: { min: [-1, -1, -1], max: [1, 1, 1] }, file: 'mock.ply' },
  { name: 'garden', gaussians: 5834784, sh_degree: 3, bounds: { min: [-9, -9, -9], max: [9, 9, 9] }, file: 'garden.ply' },
  { name: 'city', gaussians: null, sh_degree: null, bounds: null, file: 'city.spz', loaded: false },
];

// A 160 x 120 frame's depth grid, a vertex every 32 px (6 x 5): the vertices at x <= 64 are 2
// units away, those at x >= 96 are 20 (inverse depth codes 255 and 26 of 0.5).
export function twoDepthGrid() {
  const cols = 6;
  const rows = 5;
  const codes = Buffer.alloc(cols * rows);
  for (let i = 0; i < codes.length; i++) codes[i] = (i % cols) * 32 <= 64 ? 255 : 26;
  return { cols, rows, cell_px: 32, inverse_depth_max: 0.5, inverse_depth: zlib.deflateSync(codes) };
}

export function loadFixture(file = path.join(here, 'fixtures/stream_160x120.bin')) {
  const b = fs.readFileSync(file);
  const frames = [];
  for (let o = 0; o < b.length; ) {
    const n = b.readUInt32LE(o);
    frames.push({ key: b[o + 4] === 1, data: b.subarray(o + 5, o + 5 + n) });
    o += 5 + n;
  }
  return frames;
}

function wsFrame(opcode, bytes) {
  const n = bytes.length;
  let h;
  if (n < 126) h = Buffer.from([0x80 | opcode, n]);
  else if (n < 65536) {
    h = Buffer.alloc(4);
    h[0] = 0x80 | opcode;
    h[1] = 126;
    h.writeUInt16BE(n, 2);
  } else {
    h = Buffer.alloc(10);
    h[0] = 0x80 | opcode;
    h[1] = 127;
    h.writeBigUInt64BE(BigInt(n), 2);
  }
  return Buffer.concat([h, Buffer.from(bytes)]);
}

// Client frames (always masked); yields [opcode, payload] and keeps the unparsed rest.
function* parseFrames(state) {
  for (;;) {
    const buf = state.buf;
    if (buf.length < 2) return;
    let len = buf[1] & 127;
    let o = 2;
    if (len === 126) {
      if (buf.length < 4) return;
      len = buf.readUInt16BE(2);
      o = 4;
    } else if (len === 127) {
      if (buf.length < 10) return;
      len = Number(buf.readBigUInt64BE(2));
      o = 10;
    }
    if (buf.length < o + 4 + len) return;
    const mask = buf.subarray(o, o + 4);
    const payload = Buffer.from(buf.subarray(o + 4, o + 4 + len));
    for (let i = 0; i < len; i++) payload[i] ^= mask[i & 3];
    state.buf = buf.subarray(o + 4 + len);
    yield [buf[0] & 15, payload];
  }
}

export async function startMockServer({ webRoot, protoFile, port = 0 }) {
  const pb = require('protobufjs');
  const root = pb.parse(fs.readFileSync(protoFile, 'utf8'), { keepCase: true }).root;
  const SM = root.lookupType('catgs.stream.v1.ServerMessage');
  const CM = root.lookupType('catgs.stream.v1.ClientMessage');
  const frames = loadFixture();
  const received = []; // { session, path, body, msg } for the test to inspect
  let sessions = 0;
  let fullRefusals = 0;

  const server = http.createServer((req, res) => {
    let p = decodeURIComponent(new URL(req.url, 'http://x').pathname);
    if (p === '/scenes') {
      res.writeHead(200, { 'content-type': 'application/json' }).end(JSON.stringify(SCENES));
      return;
    }
    const noProto = p.startsWith('/noproto/');
    if (noProto) p = p.slice('/noproto'.length);
    if (p.endsWith('/')) p += 'index.html';
    const file = path.join(webRoot, path.normalize(p));
    const ext = path.extname(file);
    if (!file.startsWith(webRoot) || !fs.existsSync(file) || !fs.statSync(file).isFile()) {
      res.writeHead(404).end();
      return;
    }
    if (noProto && ext === '.proto') {
      res.writeHead(415).end();
      return;
    }
    res.writeHead(200, { 'content-type': MIME[ext] || 'application/octet-stream' });
    res.end(fs.readFileSync(file));
  });

  server.on('upgrade', (req, sock) => {
    const scenario = new URL(req.url, 'http://x').pathname;
    const protocols = String(req.headers['sec-websocket-protocol'] || '').split(',').map((s) => s.trim());
    if (!protocols.includes('catgs.v1')) {
      sock.end('HTTP/1.1 400 Bad Request\r\n\r\n');
      return;
    }
    const accept = crypto.createHash('sha1').update(req.headers['sec-websocket-key'] + WS_GUID).digest('base64');
    sock.write('HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n' +
      `Sec-WebSocket-Accept: ${accept}\r\nSec-WebSocket-Protocol: catgs.v1\r\n\r\n`);
    const session = ++sessions;
    const state = { buf: Buffer.alloc(0) };
    let next = 0;
    let sent = 0;
    let sentAtStats = 0;
    const send = (body) => sock.write(wsFrame(2, SM.encode(SM.fromObject(body)).finish()));
    const fail = (code, reason, retryAfterMs = 0) => {
      send({ error: { code, reason, retry_after_ms: retryAfterMs } });
      sock.end(wsFrame(8, Buffer.alloc(0)));
    };
    let statsTimer = null;
    sock.on('close', () => clearInterval(statsTimer));
    sock.on('error', () => {});
    sock.on('data', (d) => {
      state.buf = Buffer.concat([state.buf, d]);
      for (const [op, payload] of parseFrames(state)) {
        if (op === 8) {
          sock.end(wsFrame(8, Buffer.alloc(0)));
          return;
        }
        if (op !== 2) continue;
        const msg = CM.toObject(CM.decode(payload), { oneofs: true });
        received.push({ session, path: scenario, body: msg.body, msg: msg[msg.body], at: Date.now() });
        if (msg.body === 'hello') {
          if (scenario === '/ws-token' && msg.hello.token !== 'sesame') return fail(4, 'wrong or missing token');
          if (msg.hello.scene && !SCENES.some((x) => x.name === msg.hello.scene)) {
            return fail(3, `no scene '${msg.hello.scene.slice(0, 64)}' on this server (it has: ${SCENES.map((x) => x.name).join(', ')})`);
          }
          if (scenario === '/ws-full' && fullRefusals < 2) {
            fullRefusals++;
            return fail(5, 'server full (1 sessions)', 2500);
          }
          const open = () => {
            statsTimer = setInterval(() => {
              const rendered = sent > sentAtStats;
              sentAtStats = sent;
              send({ stats: { frames_sent: sent, poses_received: sent, render_ms_mean: rendered ? 12.5 : 0,
                encode_ms_mean: rendered ? 3.5 : 0, bytes_per_second: rendered ? 250000 : 0,
                encode_psnr_db_mean: rendered ? 31.5 : 0, encoder: 'x264 superfast' } });
            }, 1000);
            send({ welcome: {
              session_id: `mock-${session}`, scene_name: 'mock', renderer: 'cpu', encoder: 'x264', pipeline: 'exact',
              codec: 1, width: 160, height: 120,
              scene_bounds: { min: { x: -1, y: -1, z: -1 }, max: { x: 1, y: 1, z: 1 } },
              initial_pose: { position: { x: 0, y: 0, z: -4 }, orientation: { w: 1 }, vertical_fov_deg: 50 },
              // Not the bounds' centre: the page must orbit around this one.
              orbit_centre: { x: 0, y: 0, z: 1 }, up: { x: 0, y: -1, z: 0 }, scene_scale: 5,
            } });
          };
          if (scenario === '/ws-loading') {
            // A scene loading on first use: LoadProgress (only when the Hello asked for it), then
            // Welcome 1.5 s later.
            if (msg.hello.load_progress) {
              send({ load_progress: { scene_name: 'mock', percent: 0 } });
              setTimeout(() => send({ load_progress: { scene_name: 'mock', percent: 42, gaussians_read: 42,
                gaussians_total: 100 } }), 200);
              setTimeout(() => send({ load_progress: { scene_name: 'mock', percent: 100, gaussians_read: 100,
                gaussians_total: 100 } }), 1400);
            }
            setTimeout(open, 1500);
          } else {
            open();
            // A server draining (SIGTERM): its Stats say when the session will end.
            if (scenario === '/ws-drain') send({ stats: { frames_sent: 0, drain_ms_left: 2600 } });
          }
        } else if (msg.body === 'depth_request') {
          const d = msg.depth_request;
          send({ depth_result: { request_id: d.request_id, hit: true, point: { x: 0, y: 0, z: 1 }, depth: 5, opacity: 1 } });
        } else if (msg.body === 'key_frame_request') {
          next = 0; // the fixture's first access unit is its IDR
        } else if (msg.body === 'pose') {
          const hold = scenario === '/ws-hold' || scenario === '/ws-hold-depth';
          if (scenario === '/ws-noframes' || (hold && sent >= 1)) continue;
          let fr = frames[next];
          next = (next + 1) % frames.length;
          if (scenario === '/ws-garbage' && sent === 3) {
            // An "IDR" whose SPS names an unknown profile: the decoder must fail and recover.
            fr = { key: true, data: Buffer.from([0, 0, 0, 1, 0x67, 0xff, 0, 0x1f, 1, 0, 0, 1, 0x65, 9, 9]) };
          }
          send({ frame: { sequence: sent++, pose_sequence: msg.pose.sequence, client_time_ms: msg.pose.client_time_ms,
            key_frame: fr.key, width: 160, height: 120, payload: fr.data,
            ...(scenario === '/ws-hold-depth' ? { depth_grid: twoDepthGrid() } : {}) } });
          if (scenario === '/ws-error' && sent === 5) return fail(8, 'mock: too slow');
          if (scenario === '/ws-restart' && sent === 5) return fail(7, 'server restarting', 1200);
          if (scenario === '/ws-stop' && sent === 5) return fail(7, 'server shutting down', 1200);
        }
      }
    });
  });

  await new Promise((resolve) => server.listen(port, '127.0.0.1', resolve));
  return {
    port: server.address().port,
    received,
    close: () => new Promise((resolve) => {
      server.closeAllConnections?.();
      server.close(resolve);
    }),
  };
}
