// CaT-GS Stream viewer: sends camera poses, decodes the H.264 frames the server renders for them
// and draws them. Wiring only; the pieces live in the modules imported below.

import { OrbitCamera } from './camera.js';
import {
  Connection, defaultWebSocketUrl, ERROR_INVALID_ARGUMENT, ERROR_SERVER_FULL, ERROR_SHUTTING_DOWN, ERROR_UNAUTHORIZED,
} from './connection.js';
import { Controls } from './controls.js';
import { StreamDecoder, decodableCodecs, hasWebCodecs, CODEC_H264 } from './decoder.js';
import { Overlay } from './overlay.js';
import {
  LOADGEN_SECONDS_PER_VIEW, PathRecorder, fromInriaCameras, fromTraceFile, poseAtTime, resample, toInriaCameras,
  TOUR_SECONDS_PER_VIEW, toTraceFile, tourDuration, tourPoseAt,
} from './paths.js';
import { loadProtocol } from './protocol.js';
import { applyHomography, cssTransform, edgeFill, planeDepthFor, reprojection } from './reproject.js';
import { capViewport, parseMaxSize } from './viewport.js';
import { NotesUi } from './notes_ui.js';
import { WalkMode } from './walk.js';
import { VideoExportUi, tourSamples } from './video_export.js';
import { parseView, viewUrl, withoutView } from './view_link.js';
import { TOKEN_KEY, takeToken } from './token.js';

const $ = (id) => document.getElementById(id);
const canvas = $('view');
const ctx = canvas.getContext('2d', { alpha: false });
const params = new URLSearchParams(location.search);
const overlay = new Overlay($('stats'), $('messages'), { showStats: params.get('stats') === '1', noticeEl: $('notice') });
// ?scale=0.5 renders at half the device resolution (cheaper on a CPU renderer or a slow link);
// the quality menu changes it.
let renderScale = Math.min(Math.max(Number(params.get('scale')) || 1, 0.1), 4);
// The stream is capped (default 1920x1080, either orientation) whatever the device pixel ratio:
// a phone at DPR 3 would otherwise ask for 1170x2532. ?max=WxH moves the cap.
const maxSize = parseMaxSize(params.get('max'));
const linkView = parseView(params);
// ?scene=NAME opens that scene of a server that serves several (GET /scenes lists them).
const sceneParam = (params.get('scene') || '').slice(0, 128);
// ?codec=h264: offer only H.264 (the page otherwise offers AV1 too where WebCodecs decodes it).
const codecParam = params.get('codec') || '';
const isTouch = (navigator.maxTouchPoints || 0) > 0 || matchMedia('(pointer: coarse)').matches;
// Latency hiding (reproject.js): the last frame re-projected to the newest pose until its own
// frame arrives. ?reproject=0 turns it off.
const reprojectOn = params.get('reproject') !== '0';

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
  sentPoses: new Map(), // sequence -> the pose sent, until a frame answers it or a later one
  shownPose: null, // the pose of the frame on the canvas (null: unknown, not re-projected)
  reprojectVersion: -1, // the camera version the canvas transform was worked out for
  framesDecoded: 0,
  sessionFrames: 0,
  lastFrame: null,
  lastPoseSent: null,
  reconnectAt: 0,
  status: 'starting',
  loadProgress: null, // the last LoadProgress (the scene loading for this session)
  closeInfo: null, // the last onClose argument while not connected
  serverError: null, // the Error of the current connection, if any
  token: takeToken(location, sessionStorage, history), // and gone from the address bar
  recorder: null, // PathRecorder while recording
  recording: null, // the last finished recording (samples)
  waypoints: [],
  playback: null, // { kind: 'path' | 'tour', at(t), duration, t0 }
  urlVersion: -1,
  urlSettleAt: 0,
  maxBitrateKbps: 0, // the quality menu's ceiling (0: the server's default); sent as Quality
  unreportedLatencyMs: 0, // the newest shown frame's pose-to-frame latency, for the next Pose
  receipt: null, // { sequence, receivedMs }: the newest frame's arrival, for the next Pose
  depthRequests: new Map(), // request_id -> { resolve, reject } of DepthRequests awaiting DepthResult
  nextDepthId: 1,
  notes: null, // NotesUi: hotspots, measurement, scale
  walk: null, // WalkMode
  videoExport: null, // VideoExportUi: Export video in the Paths panel
};

function viewportSize() {
  const dpr = (window.devicePixelRatio || 1) * renderScale;
  const css = { width: canvas.clientWidth || window.innerWidth, height: canvas.clientHeight || window.innerHeight };
  return capViewport(css.width * dpr, css.height * dpr, maxSize);
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
  // The newest shown frame's latency rides along to the server's /metrics (end to end).
  const shownLatencyMs = state.unreportedLatencyMs;
  // And the newest frame's arrival: the server's rate controller reads the queue on the link
  // from these receipts (server/session/link_rate.h).
  const receipt = state.receipt || { sequence: 0, receivedMs: 0 };
  if (!send(state.protocol.encodePose({ sequence, clientTimeMs, shownLatencyMs, receipt, ...pose }))) return null;
  state.unreportedLatencyMs = 0;
  state.receipt = null;
  state.sentVersion = cam.version;
  state.sentPoses.set(sequence, { position: pose.position, orientation: pose.orientation, fovDeg: pose.fovDeg });
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

// ---- depth under a pixel (DepthRequest -> DepthResult) ----

// What lies under pixel (x, y) of a width x height view of `pose` (the server's depth probe).
// Resolves with the DepthResult (hit, point, depth, opacity, error); rejects when not connected or
// the session ends first.
function probePose(pose, width, height, x, y) {
  if (!state.sessionOpen) return Promise.reject(new Error('not connected'));
  const requestId = state.nextDepthId++;
  return new Promise((resolve, reject) => {
    state.depthRequests.set(requestId, { resolve, reject });
    if (!send(state.protocol.encodeDepthRequest({ requestId, x, y, width, height, pose }))) {
      state.depthRequests.delete(requestId);
      reject(new Error('not connected'));
    }
  });
}

// The pixel under CSS pixel (x, y) of the canvas, as the camera sees it now (the shown frame is
// re-projected to this pose): the view is the canvas's CSS box, which has the stream's aspect.
function probeCss(x, y) {
  const cam = state.camera;
  if (!cam) return Promise.reject(new Error('no view yet'));
  const w = Math.max(1, Math.round(canvas.clientWidth || window.innerWidth));
  const h = Math.max(1, Math.round(canvas.clientHeight || window.innerHeight));
  return probePose(cam.pose(), w, h, x, y);
}

function onDepthResult(msg) {
  const waiting = state.depthRequests.get(msg.request_id);
  if (!waiting) return;
  state.depthRequests.delete(msg.request_id);
  // A plain object with every field (proto3 leaves zeros out: opacity 0, no hit).
  waiting.resolve(state.protocol.root.lookupType('catgs.stream.v1.DepthResult').toObject(msg, { defaults: true }));
}

// Fly to `pose` over a second, as a tour of two views (the same interpolation).
function flyTo(pose) {
  if (!state.camera) return false;
  return playKeys('fly', [state.camera.pose(), pose], 0.5);
}

// The notes' share-link value in the address (viewUrl keeps it, the token never).
function notesLinkChanged() {
  const u = new URL(location.href);
  const v = state.notes.linkValue();
  if (v) u.searchParams.set('notes', v);
  else u.searchParams.delete('notes');
  history.replaceState(null, '', u.href);
}

// ---- connection state, in words ----

const ERROR_WORDS = {
  1: 'the server could not read a message from this page',
  2: 'the page and the server do not speak the same protocol version',
  3: 'the server rejected a request from this page',
  6: 'the server failed to render or encode',
  8: 'the connection was too slow for the stream',
  9: 'this page sent more requests than the server allows',
  10: 'the connection was idle too long',
};

const retryButton = [{ id: 'retry', label: 'retry now', onClick: () => state.connection && state.connection.retryNow() }];
let tokenForm = null;

function makeTokenForm() {
  const form = document.createElement('form');
  const input = document.createElement('input');
  input.type = 'password';
  input.name = 'token';
  input.id = 'token-input';
  input.placeholder = 'access token';
  input.autocomplete = 'current-password';
  input.setAttribute('aria-label', 'access token');
  const button = document.createElement('button');
  button.type = 'submit';
  button.textContent = 'connect';
  form.append(input, button);
  form.addEventListener('submit', (e) => {
    e.preventDefault();
    state.token = input.value.trim();
    // This tab only: the token is the user's, not the link's (shared links leave it out).
    sessionStorage.setItem(TOKEN_KEY, state.token);
    input.value = '';
    setStatus('connecting');
    state.connection.restart();
  });
  return form;
}

function setStatus(status) {
  state.status = status;
  updateStateMessage();
}

// The one message that says where the connection stands; refreshed by the loop for countdowns.
function updateStateMessage() {
  const secs = () => Math.max(0, Math.ceil((state.reconnectAt - performance.now()) / 1000));
  const when = () => (secs() > 0 ? `in ${secs()} s` : 'now');
  switch (state.status) {
    case 'connecting':
    case 'handshake':
      overlay.showMessage('state', 'connecting to the server…', 'info');
      break;
    case 'loading-scene': {
      // The server loads a scene on its first use; LoadProgress comes until Welcome.
      const p = state.loadProgress || { scene_name: '', percent: 0 };
      overlay.showMessage('state', `loading scene ${p.scene_name}: ${p.percent}%`, 'info');
      break;
    }
    case 'first-view':
      overlay.showMessage('state', 'rendering the first view…', 'info');
      break;
    case 'streaming':
      overlay.clearMessage('state');
      break;
    case 'unreachable':
      overlay.showMessage('state', `cannot reach the server, retrying ${when()}`, 'error', retryButton);
      break;
    case 'server-full':
      overlay.showMessage('state', `server full, retrying ${when()}`, 'warn', retryButton);
      break;
    case 'restarting':
    case 'stopping':
      overlay.showMessage('state', `server ${state.status}, reconnecting ${when()}`, 'warn', retryButton);
      break;
    case 'no-scene':
      // The scene picker, filled from GET /scenes, in the message: a plain choice, no retries.
      overlay.showMessage('state', `There is no scene named '${sceneParam}' on this server. Choose one:`, 'warn', sceneChoice());
      break;
    case 'needs-token':
      tokenForm = tokenForm || makeTokenForm();
      overlay.showMessage('state', state.token ? 'wrong token: enter the access token' : 'this server needs an access token',
        'error', tokenForm);
      break;
    case 'refused': {
      const e = state.closeInfo && state.closeInfo.error;
      overlay.showMessage('state', `the server refused this page: ${(e && e.reason) || 'protocol error'} (reload the page)`, 'error');
      break;
    }
    case 'disconnected': {
      const e = state.closeInfo && state.closeInfo.error;
      const why = e ? `${ERROR_WORDS[e.code] || 'the server ended the session'}${e.reason ? ` (${e.reason})` : ''}; ` : 'disconnected, ';
      overlay.showMessage('state', `${why}reconnecting ${when()}`, e ? 'error' : 'warn', retryButton);
      break;
    }
    default:
      break;
  }
}

function onWelcome(w) {
  state.welcome = w;
  state.sessionOpen = true;
  state.sessionFrames = 0;
  state.closeInfo = null;
  state.poseSequence = 0; // the initial pose is sequence 0; ours count from 1
  state.sentPoses = new Map();
  state.shownPose = null;
  canvas.style.transform = '';
  state.connection.markHealthy();
  state.decoder.reset();
  state.decoder.setWelcomeCodec(w.codec);
  overlay.setSession(w);
  // Export video only where the server would take it (an author's or admin's session on a server
  // with export built in); a viewer's request would be refused anyway.
  $('export-controls').hidden = !w.can_export;
  scenePicker.value = w.scene_name;
  // A page opened while the server was still starting got no scene list: ask again now.
  if (!scenePickerLoaded) loadScenePicker();
  // Keep the user's view across a reconnect to the same scene; start fresh otherwise.
  if (!state.camera || state.camera.sceneName !== w.scene_name) {
    state.camera = OrbitCamera.fromWelcome(w.initial_pose, w.scene_bounds, w);
    state.camera.sceneName = w.scene_name;
    if (linkView && linkView.pose && !state.linkApplied) {
      state.linkApplied = true;
      const p = linkView.pose;
      if (linkView.scene && linkView.scene !== w.scene_name) {
        notice(`this link shows a view of "${linkView.scene}"; this server shows "${w.scene_name}": starting from its view`, 'warn', 6000);
      } else {
        state.camera.setPose(p.position, p.orientation, p.fovDeg ?? state.camera.fovDeg);
      }
    }
    state.urlVersion = state.camera.version;
  }
  setStatus('first-view');
  // Answers of the last session never come: their waits end.
  rejectDepthRequests();
  // A chosen quality outlives reconnects; the default is never sent (older servers lack Quality).
  if (state.maxBitrateKbps > 0) send(state.protocol.encodeQuality(state.maxBitrateKbps));
  sendPose();
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
    backdrop.stale = true; // a new frame to continue around the re-projected one
    if (meta) {
      state.shownPose = state.sentPoses.get(meta.poseSequence) || null;
      for (const k of state.sentPoses.keys()) if (k < meta.poseSequence) state.sentPoses.delete(k);
    }
    updateReprojection();
    const now = performance.now();
    state.framesDecoded++;
    state.sessionFrames++;
    if (state.status === 'first-view') setStatus('streaming');
    const latency = meta ? now - meta.clientTimeMs : NaN;
    if (latency >= 0 && latency <= 3.6e6) state.unreportedLatencyMs = latency;
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

function rejectDepthRequests() {
  for (const w of state.depthRequests.values()) w.reject(new Error('the session ended'));
  state.depthRequests.clear();
}

function onClose(info) {
  const { code, reason, retryInMs, error, permanent, reached } = info;
  state.sessionOpen = false;
  state.receipt = null; // the next session's frames are numbered anew
  rejectDepthRequests();
  state.videoExport.onClosed();
  state.closeInfo = info;
  state.decoder.reset();
  overlay.clearSession();
  overlay.clearMessage('drain'); // the state line says what happens next
  state.reconnectAt = performance.now() + (retryInMs || 0);
  let status = 'disconnected';
  // ?scene= names a scene the server does not have (session.cpp: "no scene 'X' on this server").
  if (permanent && error && error.code === ERROR_INVALID_ARGUMENT && /^no scene '/.test(error.reason || '')) status = 'no-scene';
  else if (permanent) status = error && error.code === ERROR_UNAUTHORIZED ? 'needs-token' : 'refused';
  else if (error && error.code === ERROR_SERVER_FULL) status = 'server-full';
  // A server stopping (SIGTERM, SIGINT) cannot tell whether it comes back: "restarting" only when
  // its reason says so.
  else if (error && error.code === ERROR_SHUTTING_DOWN) status = /restart/i.test(error.reason || '') ? 'restarting' : 'stopping';
  else if (!reached) status = 'unreachable';
  setStatus(status);
  console.info(`catgs: connection closed (${code}${reason ? `: ${reason}` : ''})` +
    (permanent ? ', not retrying' : `, retry in ${retryInMs} ms`));
}

// Whether the page's thread was busy (a long task) within the last moments: a heartbeat every
// 20 ms that came more than 50 ms late, or none for 70 ms. Messages that waited behind the busy
// thread are handled right after it, whichever task runs first.
const pageBusy = {
  beatMs: performance.now(),
  busyUntilMs: 0,
  start() {
    setInterval(() => {
      const now = performance.now();
      if (now - this.beatMs > 70) this.busyUntilMs = now + 100;
      this.beatMs = now;
    }, 20);
  },
  recently() {
    const now = performance.now();
    return now - this.beatMs > 70 || now < this.busyUntilMs;
  },
};

function onMessage(kind, msg) {
  switch (kind) {
    case 'welcome':
      onWelcome(msg);
      break;
    case 'frame':
      if (!state.sessionOpen) break;
      // A receipt tells the server's rate controller when the frame arrived; read after the
      // page's thread was busy, it would say when the thread came back, and a busy page would
      // look like a slow link (issue 64): none for such a frame.
      if (!pageBusy.recently()) state.receipt = { sequence: msg.sequence, receivedMs: performance.now() };
      state.decoder.decode(msg);
      break;
    case 'stats':
      overlay.setServerStats(msg);
      // The server is shutting down (a rollout, a scale-down): say when this stream ends; the
      // reconnect then finds another replica.
      if (msg.drain_ms_left > 0) {
        overlay.showMessage('drain', `server stopping: this stream ends in ${Math.ceil(msg.drain_ms_left / 1000)} s, ` +
          'then reconnects', 'warn');
      }
      keepAlive(); // message events still run when a hidden tab's timers are throttled
      break;
    case 'error':
      // Shown when the connection closes, with what happens next (onClose).
      console.warn(`catgs: server error ${state.protocol.errorCodeName(msg.code)}: ${msg.reason}` +
        (msg.retry_after_ms ? ` (retry after ${msg.retry_after_ms} ms)` : ''));
      break;
    case 'pong':
      overlay.setRtt(performance.now() - msg.client_time_ms);
      break;
    case 'load_progress':
      state.loadProgress = msg;
      setStatus('loading-scene');
      break;
    case 'depth_result':
      onDepthResult(msg);
      break;
    case 'annotations':
      state.notes.onAnnotations(msg);
      break;
    case 'export_progress':
      state.videoExport.onProgress(msg);
      break;
    case 'export_chunk':
      state.videoExport.onChunk(msg);
      break;
    default:
      break;
  }
}

// A Ping every 2 s at most: the round-trip time for the overlay, and proof of life for the
// server, which ends a session silent for --silent-timeout-ms (60 s by default). Called from a
// timer and from each Stats message (about one a second), because browsers throttle a hidden
// tab's timers to once a minute after a while.
let lastPingMs = -Infinity;
function keepAlive() {
  const now = performance.now();
  if (!state.sessionOpen || now - lastPingMs < 1900) return;
  lastPingMs = now;
  send(state.protocol.encodePing(now));
}

function onResize() {
  const v = viewportSize();
  if (state.viewport && v.width === state.viewport.width && v.height === state.viewport.height) return;
  state.viewport = v;
  qualityStatus();
  if (state.sessionOpen && send(state.protocol.encodeResize(v.width, v.height))) resendPose();
}

// ---- view controls: reset, link, fullscreen, help ----

// A short notice: a line at the bottom centre (overlay.js), above the mouse hint while that
// is still shown.
function notice(text, level = 'info', ms = 2500) {
  const hint = $('hint');
  $('notice').style.bottom = hint.hidden ? '' : `${hint.offsetHeight + 10}px`;
  overlay.showMessage('notice', text, level);
  clearTimeout(notice.timer);
  notice.timer = setTimeout(() => overlay.clearMessage('notice'), ms);
}

function resetView() {
  const w = state.welcome;
  if (!w) return;
  stopPlayback();
  const name = state.camera ? state.camera.sceneName : w.scene_name;
  const version = state.camera ? state.camera.version + 1 : 0;
  state.camera = OrbitCamera.fromWelcome(w.initial_pose, w.scene_bounds, w);
  state.camera.sceneName = name;
  state.camera.version = version; // a new version: the loop sends it
  history.replaceState(null, '', withoutView(location.href));
  state.urlVersion = state.camera.version;
}

function shareUrl() {
  return state.camera ? viewUrl(location.href, state.camera.pose(), state.camera.sceneName) : null;
}

async function copyLink() {
  const url = shareUrl();
  if (!url) return null;
  history.replaceState(null, '', url);
  state.urlVersion = state.camera.version;
  try {
    await navigator.clipboard.writeText(url);
    notice('link to this view copied');
  } catch (_) {
    // No clipboard permission (or no secure context): the address bar holds the link now.
    notice('copy the link from the address bar');
  }
  return url;
}

// The address bar follows the view once the camera rests, so a plain copy of it shares the view.
function syncUrl(now) {
  const cam = state.camera;
  if (!cam || state.playback || cam.version === state.urlVersion) return;
  if (cam.version !== state.urlPending) {
    state.urlPending = cam.version;
    state.urlSettleAt = now + 600;
    return;
  }
  if (now < state.urlSettleAt) return;
  history.replaceState(null, '', viewUrl(location.href, cam.pose(), cam.sceneName));
  state.urlVersion = cam.version;
}

function toggleFullscreen() {
  if (document.fullscreenElement) return document.exitFullscreen().catch(() => {});
  const el = document.documentElement;
  if (!el.requestFullscreen) {
    notice('this browser has no fullscreen mode here', 'warn');
    return Promise.resolve();
  }
  return el.requestFullscreen().catch((e) => notice(`fullscreen refused: ${e.message}`, 'warn'));
}

// ---- quality menu ----

function setRenderScale(scale) {
  renderScale = scale;
  onResize();
  qualityStatus();
}

function setMaxBitrate(kbps) {
  state.maxBitrateKbps = kbps;
  // The encoder restarts with it (an IDR follows); the current pose again makes that frame.
  if (state.sessionOpen && send(state.protocol.encodeQuality(kbps))) resendPose();
  qualityStatus();
}

function qualityStatus() {
  const v = state.viewport;
  $('quality-status').textContent = v ? `stream ${v.width}x${v.height}` : '';
}

function togglePanel(id, buttonId, show) {
  const panel = $(id);
  const open = show ?? panel.hidden;
  // One panel at a time: they all sit under the toolbar.
  for (const [p, b] of [['paths', 'btn-paths'], ['notes', 'btn-notes'], ['helppanel', 'btn-help'], ['quality', 'btn-quality']]) {
    $(p).hidden = p === id ? !open : true;
    $(b).setAttribute('aria-expanded', String(p === id && open));
  }
  if (open) placePanel();
  if (!open) canvas.focus();
  return open;
}

// The open panel sits below the toolbar (which wraps to two rows on a narrow window), and below
// the stats (?stats=1) where they share columns, so that it never covers them; it scrolls within
// the window. Again whenever the toolbar or the stats change size (wireUi).
function placePanel() {
  const panel = document.querySelector('.panel:not([hidden])');
  if (!panel) return;
  let top = Math.ceil($('toolbar').getBoundingClientRect().bottom) + 4;
  const stats = $('stats');
  if (!stats.hidden) {
    const s = stats.getBoundingClientRect();
    const p = panel.getBoundingClientRect();
    if (s.left < p.right && p.left < s.right) top = Math.max(top, Math.ceil(s.bottom) + 4);
  }
  panel.style.top = `${top}px`;
  panel.style.maxHeight = `calc(100vh - ${top + 6}px)`;
}

// A phone (a touch screen at most 600 CSS px wide, style.css): the toolbar keeps one row of
// buttons a finger can hit, and Link, Paths, Quality and the scene picker go under More.
function wireMenu() {
  const bar = $('toolbar');
  const setOpen = (open) => {
    bar.classList.toggle('menu-open', open);
    $('btn-menu').setAttribute('aria-expanded', String(open));
  };
  $('btn-menu').addEventListener('click', () => setOpen(!bar.classList.contains('menu-open')));
  // A button of the menu closes it before its own action (capture: a panel opened by it is then
  // placed below the one-row toolbar).
  bar.addEventListener('click', (e) => e.target.closest('button.more') && setOpen(false), true);
  canvas.addEventListener('pointerdown', () => setOpen(false));
  window.addEventListener('keydown', (e) => e.key === 'Escape' && setOpen(false));
  document.body.classList.toggle('touch', isTouch);
  const observer = new ResizeObserver(placePanel);
  observer.observe(bar);
  observer.observe($('stats'));
  window.addEventListener('resize', placePanel);
}

// ---- camera paths ----

function pathsStatus() {
  const rec = state.recorder
    ? `recording ${state.recorder.duration.toFixed(1)} s`
    : state.recording
      ? `path ${state.recording[state.recording.length - 1].t.toFixed(1)} s, ${state.recording.length} poses`
      : 'no path recorded';
  const play = state.playback ? ` · playing ${state.playback.kind}` : '';
  $('paths-status').textContent = `${rec} · ${state.waypoints.length} waypoint${state.waypoints.length === 1 ? '' : 's'}${play}`;
  $('btn-record').textContent = state.recorder ? 'Stop' : 'Record';
  $('btn-record').setAttribute('aria-pressed', String(!!state.recorder));
}

function toggleRecording() {
  if (state.recorder) {
    const r = state.recorder;
    state.recorder = null;
    if (r.samples.length) state.recording = r.samples;
  } else if (state.camera) {
    stopPlayback();
    state.recorder = new PathRecorder();
    state.recorder.add(performance.now(), state.camera.pose());
  }
  pathsStatus();
}

function play(kind) {
  if (!state.camera) return false;
  if (state.recorder) toggleRecording();
  let playback = null;
  if (kind === 'path' && state.recording && state.recording.length) {
    const s = state.recording;
    playback = { kind, duration: s[s.length - 1].t, at: (t) => poseAtTime(s, t) };
  } else if (kind === 'tour' && state.waypoints.length >= 2) {
    return playKeys('tour', state.waypoints.slice());
  }
  if (!playback) {
    notice(kind === 'tour' ? 'add at least 2 views for a tour' : 'record a path first', 'warn');
    return false;
  }
  playback.t0 = performance.now();
  state.playback = playback;
  pathsStatus();
  return true;
}

// Plays waypoints `keys` as a tour (secondsPerView apart). Waypoints of hotspots (`hotspot`: an
// id) show that hotspot's card as the tour reaches them.
function playKeys(kind, keys, secondsPerView = 2) {
  if (!state.camera || keys.length < 2) return false;
  if (state.recorder) toggleRecording();
  state.playback = {
    kind,
    duration: tourDuration(keys, secondsPerView),
    at: (t) => tourPoseAt(keys, t, secondsPerView),
    keys,
    secondsPerView,
    shown: -1,
    t0: performance.now(),
  };
  pathsStatus();
  return true;
}

// A hotspot tour: its waypoints become the tour (so tour.json exports them) and it plays.
function playHotspotTour(keys) {
  state.waypoints = keys;
  return playKeys('tour', keys);
}

function stopPlayback() {
  if (!state.playback) return;
  state.playback = null;
  pathsStatus();
}

function addWaypoint() {
  if (!state.camera) return 0;
  state.waypoints.push(state.camera.pose());
  pathsStatus();
  return state.waypoints.length;
}

function exportCameras(which) {
  const v = state.viewport;
  let poses;
  if (which === 'tour') poses = state.waypoints;
  // One view per LOADGEN_SECONDS_PER_VIEW: catgs-loadgen's cameras: replays it at recorded speed.
  else poses = state.recording ? resample(state.recording, LOADGEN_SECONDS_PER_VIEW) : [];
  if (poses.length < 2) return null; // the core's interpolation needs 2 views
  return JSON.stringify(toInriaCameras(poses, v.width, v.height, which === 'tour' ? 'tour' : 'path'), null, 1) + '\n';
}

function exportTrace() {
  const v = state.viewport;
  return state.recording ? toTraceFile(state.recording, v.width, v.height) : null;
}

function download(name, text) {
  if (!text) {
    notice(name.endsWith('.trace') || name.startsWith('path') ? 'record a path first' : 'add at least 2 views first', 'warn');
    return;
  }
  const a = document.createElement('a');
  a.href = URL.createObjectURL(new Blob([text], { type: name.endsWith('.json') ? 'application/json' : 'text/plain' }));
  a.download = name;
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}

// cameras.json holds sparse views: they become tour waypoints; a trace is a timed path.
function importText(name, text) {
  try {
    if (/^\s*\[/.test(text)) {
      state.waypoints = fromInriaCameras(text);
      notice(`${name}: ${state.waypoints.length} views as tour waypoints`);
    } else {
      state.recording = fromTraceFile(text);
      notice(`${name}: path of ${state.recording.length} poses`);
    }
    pathsStatus();
    return true;
  } catch (e) {
    notice(`${name}: ${e.message}`, 'error', 5000);
    return false;
  }
}

// ---- loop ----

// One step of the loop: playback or held keys, send the pose if the camera moved, record it,
// refresh the overlay.
let lastStepMs = performance.now();
let lastOverlayMs = 0;
function step(now) {
  const dt = (now - lastStepMs) / 1000;
  lastStepMs = now;
  const cam = state.camera;
  if (state.playback && cam) {
    const t = (now - state.playback.t0) / 1000;
    const pb = state.playback;
    const p = pb.at(Math.min(t, pb.duration));
    cam.setPose(p.position, p.orientation, p.fovDeg);
    // A hotspot waypoint reached: its card.
    if (pb.keys) {
      const k = Math.round(Math.min(t, pb.duration) / pb.secondsPerView);
      if (k !== pb.shown && Math.abs(t - k * pb.secondsPerView) < 0.25 && pb.keys[k] && pb.keys[k].hotspot) {
        pb.shown = k;
        state.notes.showCard(state.notes.hotspots.find((h) => h.id === pb.keys[k].hotspot));
      }
    }
    if (t >= pb.duration) stopPlayback();
  } else if (state.walk.on) {
    state.walk.update(dt, state.controls.keys, state.controls.shiftHeld, now);
  } else {
    state.controls.update(dt);
  }
  state.notes.update();
  if (cam && cam.version !== state.sentVersion) sendPose();
  if (cam && cam.version !== state.reprojectVersion) updateReprojection();
  if (state.recorder && cam) state.recorder.add(now, cam.pose());
  if (now - lastOverlayMs > 250) {
    lastOverlayMs = now;
    overlay.render(now);
    updateStateMessage();
    syncUrl(now);
    if (state.recorder) pathsStatus();
  }
}

// Shows the canvas's frame re-projected from its pose to the camera's (reproject.js), as a CSS
// transform of the canvas; none when they are the same pose, when the frame's pose is unknown,
// or when a corner would fall behind the new camera (a large turn: better the plain frame).
function updateReprojection() {
  const cam = state.camera;
  state.reprojectVersion = cam ? cam.version : -1;
  const from = state.shownPose;
  const w = canvas.width;
  const h = canvas.height;
  let transform = '';
  let shown = null; // the homography shown
  if (reprojectOn && cam && from && w > 0 && h > 0) {
    const to = cam.pose();
    const same =
      from.fovDeg === to.fovDeg &&
      from.position.every((v, i) => v === to.position[i]) &&
      from.orientation.every((v, i) => v === to.orientation[i]);
    if (!same) {
      // Walk mode orbits about a point just ahead (looking around): the scene's depth is the
      // probes' instead, or a frame would be re-projected as if the world were that near.
      const depth = state.walk.on ? state.walk.sceneDepth(cam) : planeDepthFor(from, cam.target, cam.sceneScale);
      const H = reprojection(from, to, depth, w, h);
      const corners = [[0, 0], [w, 0], [0, h], [w, h]].map(([x, y]) => applyHomography(H, x, y));
      if (corners.every((c) => c !== null)) {
        transform = cssTransform(H, w, h, canvas.clientWidth, canvas.clientHeight);
        shown = H;
      }
    }
  }
  if (canvas.style.transform !== transform) canvas.style.transform = transform;
  fillBackdrop(shown);
}

// Where the re-projected frame no longer covers the window (a turn or pan uncovers an edge, a
// zoom-out all four): the frame's nearest edge continued (reproject.js edgeFill), not black. A
// small canvas behind the view (256 pixels across at most: about 1 ms a camera move) that CSS
// stretches to the window.
const backdrop = { el: $('backdrop'), ctx: null, out: null, small: null, src: null, stale: true };
function fillBackdrop(H) {
  const el = backdrop.el;
  if (!H) {
    el.hidden = true;
    return;
  }
  const w = canvas.width;
  const h = canvas.height;
  const k = Math.min(1, 256 / Math.max(w, h));
  const bw = Math.max(1, Math.round(w * k));
  const bh = Math.max(1, Math.round(h * k));
  if (!backdrop.ctx || el.width !== bw || el.height !== bh) {
    el.width = bw;
    el.height = bh;
    backdrop.ctx = backdrop.ctx || el.getContext('2d');
    backdrop.out = backdrop.ctx.createImageData(bw, bh);
    backdrop.stale = true;
  }
  if (backdrop.stale) {
    // The shown frame at that size, read once per frame (the canvas holds it).
    if (!backdrop.small) {
      backdrop.small = document.createElement('canvas');
      backdrop.smallCtx = backdrop.small.getContext('2d', { willReadFrequently: true });
    }
    backdrop.small.width = bw;
    backdrop.small.height = bh;
    backdrop.smallCtx.drawImage(canvas, 0, 0, bw, bh);
    backdrop.src = backdrop.smallCtx.getImageData(0, 0, bw, bh);
    backdrop.stale = false;
  }
  if (edgeFill(H, w, h, backdrop.src, backdrop.out)) backdrop.ctx.putImageData(backdrop.out, 0, 0);
  el.hidden = false;
}

function loop(now) {
  step(now);
  requestAnimationFrame(loop);
}

function onKey(e) {
  const t = e.target;
  // Keys typed into a field are its own, but Esc: it closes the form or panel the field is in.
  if (t && (t.tagName === 'INPUT' || t.tagName === 'TEXTAREA' || t.isContentEditable) && e.key !== 'Escape') return;
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  switch (e.key) {
    case 'r':
    case 'R':
      resetView();
      break;
    case 'f':
    case 'F':
      toggleFullscreen();
      break;
    case 'c':
    case 'C':
      copyLink();
      break;
    case 'p':
    case 'P':
      togglePanel('paths', 'btn-paths');
      break;
    case 'n':
    case 'N':
      togglePanel('notes', 'btn-notes');
      break;
    case 'm':
    case 'M':
      togglePanel('notes', 'btn-notes', true);
      state.notes.setMode('measure');
      break;
    case 'g':
    case 'G':
      toggleWalk();
      break;
    case 'h':
    case 'H':
    case '?':
      togglePanel('helppanel', 'btn-help');
      break;
    case 'Escape':
      stopPlayback();
      // The new hotspot's form, or adding a hotspot or measuring, ends (the Notes panel comes
      // back); else every panel closes.
      if (!state.notes.escape()) togglePanel('paths', 'btn-paths', false);
      break;
    default:
      return;
  }
  e.preventDefault();
}

// A /scenes entry as the picker shows it. A scene not loaded yet whose format cannot be peeked
// has `gaussians: null`: its name alone, rather than a made-up "(0.00 M)".
function sceneLabel(s) {
  const n = s.gaussians;
  if (typeof n !== 'number' || !Number.isFinite(n)) return String(s.name);
  return `${s.name} (${(n / 1e6).toFixed(2)} M)`;
}

// A server with several scenes lists them at GET /scenes: the picker shows them, and choosing
// one reopens the page on it (?scene=NAME; a view in the URL belongs to the old scene and goes).
// Set once the picker holds the server's scenes (two or more, or one when the page asked for a
// scene the server lacks); until then every Welcome asks.
let scenePickerLoaded = false;
let scenePickerAsking = false;
let sceneMinimum = 2; // one scene is no choice, unless the page asked for another
let sceneForm = null;
const scenePicker = $('scene-picker'); // (held: it may be out of the page, moving to the message)

// ?scene=NAME of a scene the server lacks: the picker, moved from the toolbar into the message
// (in a form: the messages take no pointer otherwise), with every scene the server has.
function sceneChoice() {
  if (!sceneForm) {
    sceneForm = document.createElement('form');
    sceneForm.addEventListener('submit', (e) => e.preventDefault());
    sceneForm.append(scenePicker);
    sceneMinimum = 1;
    if (!scenePickerLoaded && !scenePickerAsking) loadScenePicker();
  }
  return sceneForm;
}

async function loadScenePicker() {
  if (scenePickerLoaded || scenePickerAsking) return;
  scenePickerAsking = true;
  try {
    await fillScenePicker();
  } finally {
    scenePickerAsking = false;
  }
}

async function fillScenePicker() {
  const picker = scenePicker;
  let scenes = [];
  try {
    const res = await fetch(new URL('scenes', location.href), { cache: 'no-cache' });
    if (res.ok) scenes = await res.json();
  } catch {
    return; // an older server, or none: no picker
  }
  // (sceneMinimum is read after the answer: the no-scene message may have come meanwhile.)
  if (!Array.isArray(scenes) || scenes.length < sceneMinimum) return;
  picker.replaceChildren();
  const current = (state.welcome && state.welcome.scene_name) || sceneParam || String(scenes[0].name);
  if (!scenes.some((s) => String(s.name) === current)) {
    // A scene the server lacks: no blank picker, an invitation to choose.
    const o = new Option('choose a scene…', '', true, true);
    o.disabled = true;
    picker.append(o);
  }
  for (const s of scenes) {
    const o = document.createElement('option');
    o.value = String(s.name);
    o.textContent = sceneLabel(s);
    picker.append(o);
  }
  if (scenes.some((s) => String(s.name) === current)) picker.value = current;
  picker.hidden = false;
  scenePickerLoaded = true;
}

function chooseScene() {
  const picker = scenePicker;
  if (!picker.value) return;
  const url = new URL(withoutView(location.href));
  url.searchParams.set('scene', picker.value);
  location.assign(url.href);
}

// The hint line at the bottom: the controls of the mode the view is in (orbit or walk).
function hintText(walking) {
  if (walking) return isTouch ? 'pad: walk · 1 finger: look · Walk: leave walk' : 'drag: look · WASD: walk · Shift: run · G: leave walk';
  return isTouch
    ? '1 finger: orbit · 2 fingers: zoom, pan · ? help'
    : 'drag: orbit · right-drag: pan · wheel: zoom · WASD: fly · H: help';
}

function wireUi() {
  $('hint').textContent = hintText(false);
  $('btn-reset').addEventListener('click', resetView);
  $('btn-link').addEventListener('click', copyLink);
  scenePicker.addEventListener('change', chooseScene);
  loadScenePicker();
  wireMenu();
  $('btn-fullscreen').addEventListener('click', toggleFullscreen);
  $('btn-help').addEventListener('click', () => togglePanel('helppanel', 'btn-help'));
  $('btn-paths').addEventListener('click', () => togglePanel('paths', 'btn-paths'));
  $('btn-quality').addEventListener('click', () => togglePanel('quality', 'btn-quality'));
  $('btn-notes').addEventListener('click', () => togglePanel('notes', 'btn-notes'));
  $('btn-walk').addEventListener('click', toggleWalk);
  // A click (no drag) on the scene picks a point while adding a hotspot or measuring.
  let downAt = null;
  canvas.addEventListener('pointerdown', (e) => (downAt = { x: e.clientX, y: e.clientY }));
  canvas.addEventListener('pointerup', (e) => {
    if (!downAt || !state.notes.mode) return;
    const moved = Math.hypot(e.clientX - downAt.x, e.clientY - downAt.y);
    downAt = null;
    if (moved > 4) return;
    const b = canvas.getBoundingClientRect();
    state.notes.pick(e.clientX - b.left, e.clientY - b.top);
  });
  const scaleSelect = $('quality-scale');
  if (![...scaleSelect.options].some((o) => Number(o.value) === renderScale)) {
    scaleSelect.add(new Option(`${Math.round(renderScale * 100)}% (?scale)`, String(renderScale)), 0);
  }
  scaleSelect.value = String(renderScale);
  scaleSelect.addEventListener('change', () => setRenderScale(Number(scaleSelect.value)));
  $('quality-bitrate').addEventListener('change', (e) => setMaxBitrate(Number(e.target.value)));
  $('btn-record').addEventListener('click', toggleRecording);
  $('btn-play-path').addEventListener('click', () => play('path'));
  $('btn-add-waypoint').addEventListener('click', addWaypoint);
  $('btn-play-tour').addEventListener('click', () => play('tour'));
  $('btn-clear-tour').addEventListener('click', () => {
    state.waypoints = [];
    pathsStatus();
  });
  $('btn-export-cameras').addEventListener('click', () => download('path_cameras.json', exportCameras('path')));
  $('btn-export-trace').addEventListener('click', () => download('path.trace', exportTrace()));
  $('btn-export-tour').addEventListener('click', () => download('tour_cameras.json', exportCameras('tour')));
  $('import-file').addEventListener('change', async (e) => {
    const f = e.target.files && e.target.files[0];
    if (f) importText(f.name, await f.text());
    e.target.value = '';
  });
  window.addEventListener('keydown', onKey);
  // Touching the view takes it back from a playing path or tour.
  canvas.addEventListener('pointerdown', stopPlayback);
  // The hint has done its job once the view was moved (the help panel keeps the details).
  const hideHint = () => ($('hint').hidden = true);
  canvas.addEventListener('pointerdown', hideHint, { once: true });
  canvas.addEventListener('wheel', hideHint, { once: true, passive: true });
  pathsStatus();
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
    // The codecs the page offered in Hello (decoder.js decodableCodecs, or ?codec=h264).
    get codecs() {
      return state.codecs ? [...state.codecs] : [];
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
    shareUrl,
    resetView,
    // Camera paths: the same actions as the Paths panel, files returned as text.
    toggleRecording,
    get recording() {
      return state.recording ? state.recording.map((s) => ({ ...s })) : null;
    },
    addWaypoint,
    play,
    get playing() {
      return state.playback ? state.playback.kind : null;
    },
    exportCameras,
    exportTrace,
    importText,
    setRenderScale,
    setMaxBitrate,
    // Hotspots, measurement, walk mode (issue 38).
    probe: probeCss, // (cssX, cssY) -> Promise<DepthResult as an object>
    probePose,
    get notes() {
      return state.notes.snapshot();
    },
    setNotesMode: (mode) => state.notes.setMode(mode),
    pick: (x, y) => state.notes.pick(x, y),
    addHotspot: (title, text, keepView) => state.notes.addHotspot(title, text, keepView),
    openHotspot: (id) => state.notes.open(id),
    hotspotTour: () => state.notes.tour(),
    setScale: (metres) => state.notes.setScale(metres),
    saveNotes: () => state.notes.save(),
    toggleWalk,
    get walk() {
      return state.walk.snapshot();
    },
    walkTrace: (on) => state.walk.takeTrace(on), // starts a trace of walk steps (on), or ends it: the steps
    // Export video: (options { size: 'WxH', fps, pipeline }) -> export id; its state.
    exportVideo: (options) => state.videoExport.start(options),
    cancelExport: () => state.videoExport.cancel(),
    get videoExport() {
      return state.videoExport.snapshot();
    },
  };
}

function toggleWalk() {
  stopPlayback();
  const on = state.walk.toggle();
  $('btn-walk').setAttribute('aria-pressed', String(on));
  // The hint says walk mode's controls while it is on (shown again: they are new), then the
  // orbit's again (hidden as it was before, if it had done its job).
  const hint = $('hint');
  if (on) state.hintHiddenBeforeWalk = hint.hidden;
  hint.textContent = hintText(on);
  hint.hidden = on ? false : !!state.hintHiddenBeforeWalk;
  notice(on ? 'walk mode: WASD / arrows walk, drag looks around, G leaves it' : 'walk mode off');
  return on;
}

async function main() {
  pageBusy.start();
  state.notes = new NotesUi({
    camera: () => state.camera,
    probe: probeCss,
    notice,
    flyTo,
    playTour: playHotspotTour,
    save: (json) => state.sessionOpen && send(state.protocol.encodeSaveAnnotations(json)),
    linkChanged: notesLinkChanged,
    closePanel: () => togglePanel('notes', 'btn-notes', false),
    openPanel: () => togglePanel('notes', 'btn-notes', true),
    clearNotice: () => overlay.clearMessage('notice'),
  });
  state.notes.fromLink(params.get('notes'));
  state.walk = new WalkMode({
    camera: () => state.camera,
    probePose,
    metresPerUnit: () => state.notes.metresPerUnit,
    notice,
  }, isTouch ? $('walk-pad') : null); // the pad only where fingers walk; keys elsewhere
  state.videoExport = new VideoExportUi({
    send,
    protocol: () => state.protocol,
    // The recorded path, else the tour (the page's pace between views).
    samples: () => state.recording && state.recording.length >= 2
      ? state.recording
      : state.waypoints.length >= 2 ? tourSamples(state.waypoints, TOUR_SECONDS_PER_VIEW) : null,
    notice,
  });
  installTestHook();
  wireUi();
  state.viewport = viewportSize();
  canvas.width = state.viewport.width;
  canvas.height = state.viewport.height;
  qualityStatus();
  if (!hasWebCodecs()) {
    state.status = 'unsupported';
    overlay.showMessage('state', 'This browser cannot decode H.264 with WebCodecs (VideoDecoder is missing). Use a recent Chromium, Edge or Chrome over https or localhost.');
    overlay.render();
    return;
  }
  if (linkView && linkView.error) notice(`the view in this link was ignored: ${linkView.error}`, 'warn', 6000);
  try {
    state.protocol = await loadProtocol(globalThis.protobuf);
  } catch (e) {
    state.status = 'error';
    overlay.showMessage('state', `cannot start: ${e.message}`);
    overlay.render();
    return;
  }
  state.codecs = codecParam === 'h264' ? [CODEC_H264] : await decodableCodecs();
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
      setStatus('handshake');
      onResize(); // the window may have changed while disconnected
      const v = state.viewport;
      send(state.protocol.encodeHello({
        width: v.width, height: v.height, token: state.token, scene: sceneParam, loadProgress: true,
        codecs: state.codecs,
      }));
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
  setInterval(keepAlive, 2000);
  // requestAnimationFrame stops in hidden tabs; a slow timer keeps poses and the overlay going.
  setInterval(() => {
    const now = performance.now();
    if (now - lastStepMs > 250) step(now);
  }, 100);
  setStatus('connecting');
  state.connection.connect();
  requestAnimationFrame(loop);
}

main();
