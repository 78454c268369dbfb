// CaT-GS Stream viewer: sends camera poses, decodes the H.264 frames the server renders for them
// and draws them. Wiring only; the pieces live in the modules imported below.

import { OrbitCamera } from './camera.js';
import { Connection, defaultWebSocketUrl } from './connection.js';
import { Controls } from './controls.js';
import { StreamDecoder, hasWebCodecs } from './decoder.js';
import { Overlay } from './overlay.js';
import { loadProtocol } from './protocol.js';

const canvas = document.getElementById('view');
const ctx = canvas.getContext('2d', { alpha: false });
const overlay = new Overlay(document.getElementById('stats'), document.getElementById('messages'));
const params = new URLSearchParams(location.search);
// ?scale=0.5 renders at half the device resolution (cheaper on a CPU renderer or a slow link).
const renderScale = Math.min(Math.max(Number(params.get('scale')) || 1, 0.1), 4);

const state = {
  protocol: null,
  connection: null,
  decoder: null,
  camera: null,
  welcome: null,
  sessionOpen: false,
  viewport: null,
  poseSequence: 0,
  sentVersion: -1,
  framesDecoded: 0,
  framesDropped: 0,
  lastFrame: null,
  lastPoseSent: null,
  reconnectAt: 0,
  status: 'starting',
};

// Viewport in device pixels, even (the encoder needs 4:2:0 chroma) and within the protocol's
// 16..4096 range.
function viewportSize() {
  const dpr = (window.devicePixelRatio || 1) * renderScale;
  const even = (v) => Math.min(4096, Math.max(16, Math.floor((v * dpr) / 2) * 2));
  return { width: even(canvas.clientWidth || window.innerWidth), height: even(canvas.clientHeight || window.innerHeight) };
}

function send(bytes) {
  return state.connection ? state.connection.send(bytes) : false;
}

function sendPose() {
  const cam = state.camera;
  if (!cam || !state.sessionOpen) return null;
  // Poses are tiny; a large send buffer means the link is stalled, and the newest pose will go
  // out once it drains (latest wins anyway).
  if (state.connection.bufferedAmount > 256 * 1024) return null;
  const pose = cam.pose();
  const sequence = ++state.poseSequence;
  const clientTimeMs = performance.now();
  if (!send(state.protocol.encodePose({ sequence, clientTimeMs, ...pose }))) return null;
  state.sentVersion = cam.version;
  state.lastPoseSent = { sequence, clientTimeMs, position: pose.position, orientation: pose.orientation, fovDeg: pose.fovDeg };
  return sequence;
}

// The server renders only when a pose arrives (a KeyFrameRequest or Resize just marks the next
// frame as an IDR), so both are followed by the current pose again, even if the camera is still.
function resendPose() {
  state.sentVersion = -1;
  return sendPose();
}

function requestKeyFrame() {
  if (!state.sessionOpen) return null;
  send(state.protocol.encodeKeyFrameRequest());
  return resendPose();
}

function onWelcome(w) {
  state.welcome = w;
  state.sessionOpen = true;
  state.poseSequence = 0; // the initial pose is sequence 0; ours count from 1
  state.connection.markHealthy();
  state.decoder.reset();
  overlay.clearMessage('connection');
  overlay.clearMessage('server', 8000);
  overlay.setSession(w, state.protocol.codecName(w.codec));
  // Keep the user's view across a reconnect to the same scene; start fresh otherwise.
  if (!state.camera || state.camera.sceneName !== w.scene_name) {
    state.camera = OrbitCamera.fromWelcome(w.initial_pose, w.scene_bounds);
    state.camera.sceneName = w.scene_name;
  }
  state.status = 'streaming';
  sendPose();
}

function onFrame(f) {
  state.decoder.decode(f);
}

function drawFrame(frame, meta) {
  try {
    const w = frame.displayWidth;
    const h = frame.displayHeight;
    // The backing store follows the stream so the canvas holds the frame pixel for pixel; CSS
    // stretches it to the window.
    if (canvas.width !== w || canvas.height !== h) {
      canvas.width = w;
      canvas.height = h;
    }
    ctx.drawImage(frame, 0, 0, w, h);
    const now = performance.now();
    state.framesDecoded++;
    const latency = meta ? now - meta.clientTimeMs : NaN;
    state.lastFrame = {
      poseSequence: meta ? meta.poseSequence : -1,
      sequence: meta ? meta.sequence : -1,
      width: w,
      height: h,
      keyFrame: meta ? meta.keyFrame : false,
      latencyMs: latency,
    };
    overlay.frameDrawn(now, latency, w, h, state.decoder.codec);
  } finally {
    frame.close(); // VideoFrames hold decoder memory until closed
  }
}

function onClose({ code, reason, retryInMs }) {
  state.sessionOpen = false;
  state.status = 'disconnected';
  state.decoder.reset();
  overlay.clearSession();
  state.reconnectAt = performance.now() + retryInMs;
  updateReconnectMessage();
  console.info(`catgs: connection closed (${code}${reason ? `: ${reason}` : ''}), retry in ${retryInMs} ms`);
}

function updateReconnectMessage() {
  if (state.status !== 'disconnected') return;
  const s = Math.max(0, Math.ceil((state.reconnectAt - performance.now()) / 1000));
  overlay.showMessage('connection', s > 0 ? `disconnected, reconnecting in ${s} s` : 'disconnected, reconnecting now', 'warn');
}

function onMessage(kind, msg) {
  switch (kind) {
    case 'welcome':
      onWelcome(msg);
      break;
    case 'frame':
      if (state.sessionOpen) onFrame(msg);
      break;
    case 'stats':
      overlay.setServerStats(msg);
      break;
    case 'error': {
      const name = state.protocol.errorCodeName(msg.code);
      overlay.showMessage('server', `server error ${name} (${msg.code}): ${msg.reason || 'no reason given'}`);
      console.warn(`catgs: server error ${name}: ${msg.reason}`);
      break;
    }
    case 'pong':
      overlay.setRtt(performance.now() - msg.client_time_ms);
      break;
    default:
      break;
  }
}

function onResize() {
  const v = viewportSize();
  if (state.viewport && v.width === state.viewport.width && v.height === state.viewport.height) return;
  state.viewport = v;
  if (state.sessionOpen && send(state.protocol.encodeResize(v.width, v.height))) resendPose();
}

// One step of the loop: apply held keys, send the pose if the camera moved, refresh the overlay.
let lastStepMs = performance.now();
let lastOverlayMs = 0;
function step(now) {
  const dt = (now - lastStepMs) / 1000;
  lastStepMs = now;
  state.controls.update(dt);
  if (state.camera && state.camera.version !== state.sentVersion) sendPose();
  if (now - lastOverlayMs > 250) {
    lastOverlayMs = now;
    overlay.render(now);
    updateReconnectMessage();
  }
}

function loop(now) {
  step(now);
  requestAnimationFrame(loop);
}

function installTestHook() {
  // A small, stable surface for the e2e test (and the console) to drive the page
  // deterministically.
  window.catgs = {
    get framesDecoded() {
      return state.framesDecoded;
    },
    get lastFrame() {
      return state.lastFrame ? { ...state.lastFrame } : null;
    },
    get lastPoseSent() {
      return state.lastPoseSent ? { ...state.lastPoseSent } : null;
    },
    get welcome() {
      return state.welcome && state.protocol
        ? state.protocol.root.lookupType('catgs.stream.v1.Welcome').toObject(state.welcome, { defaults: true })
        : null;
    },
    get status() {
      return state.status;
    },
    get connected() {
      return state.sessionOpen;
    },
    get viewport() {
      return state.viewport ? { ...state.viewport } : null;
    },
    get decoderErrors() {
      return state.decoder ? state.decoder.errors : 0;
    },
    // Sets the camera and sends the pose at once; returns its sequence (null if not connected).
    setPose(position, orientation, fovDeg) {
      if (!state.camera) throw new Error('no session yet');
      state.camera.setPose(position, orientation, fovDeg);
      return sendPose();
    },
    pose() {
      return state.camera ? state.camera.pose() : null;
    },
    // Asks for an IDR and re-sends the current pose; returns that pose's sequence.
    requestKeyFrame() {
      return requestKeyFrame();
    },
    overlayText() {
      return overlay.text();
    },
    // The canvas as a PNG data URL: exactly the decoded pixels, without the overlay on top.
    snapshot() {
      return canvas.toDataURL('image/png');
    },
  };
}

async function main() {
  installTestHook();
  state.viewport = viewportSize();
  canvas.width = state.viewport.width;
  canvas.height = state.viewport.height;
  if (!hasWebCodecs()) {
    state.status = 'unsupported';
    overlay.showMessage('webcodecs', 'This browser cannot decode H.264 with WebCodecs (VideoDecoder is missing). Use a recent Chromium, Edge or Chrome over https or localhost.');
    overlay.render();
    return;
  }
  try {
    state.protocol = await loadProtocol(globalThis.protobuf);
  } catch (e) {
    state.status = 'error';
    overlay.showMessage('protocol', `cannot start: ${e.message}`);
    overlay.render();
    return;
  }
  state.decoder = new StreamDecoder({
    onFrame: drawFrame,
    onError: (e) => {
      console.warn('catgs: decoder error, requesting a key frame:', e);
      overlay.showMessage('decoder', `decoder error (${e.message || e}); waiting for a key frame`, 'warn');
      setTimeout(() => overlay.clearMessage('decoder'), 3000);
    },
    requestKeyFrame,
  });
  state.controls = new Controls(canvas, () => state.camera);
  state.connection = new Connection(defaultWebSocketUrl(location), state.protocol, {
    onOpen: () => {
      state.status = 'handshake';
      onResize(); // the window may have changed while disconnected
      const v = state.viewport;
      send(state.protocol.encodeHello({ width: v.width, height: v.height, token: params.get('token') || '' }));
    },
    onMessage,
    onClose,
    onProtocolError: (e) => console.warn('catgs: bad message from the server:', e),
  });
  let resizeTimer = null;
  window.addEventListener('resize', () => {
    clearTimeout(resizeTimer);
    resizeTimer = setTimeout(onResize, 150); // one Resize per gesture, not one per pixel
  });
  setInterval(() => {
    if (state.sessionOpen) send(state.protocol.encodePing(performance.now()));
  }, 2000);
  // requestAnimationFrame stops in hidden tabs; a slow timer keeps poses and the overlay going.
  setInterval(() => {
    const now = performance.now();
    if (now - lastStepMs > 250) step(now);
  }, 100);
  state.status = 'connecting';
  state.connection.connect();
  requestAnimationFrame(loop);
}

main();
