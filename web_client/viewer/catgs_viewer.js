// CatgsViewer (issue 63): one CaT-GS stream in a canvas, for any page. It owns the connection
// (Hello, reconnect with backoff, the server's retry hints), the decoding (WebCodecs), the canvas
// (latency hiding: display.js), the camera and its controls, and the session's upkeep: poses
// with their receipts (none after a busy page moment: page_busy.js), Pings, Resize. The full page
// (app.js) is built on it, as is the <catgs-viewer> element (viewer.js); README.md documents the
// options, events and methods.
//
// Events (CustomEvent, `detail` as in README.md): connected, frame, stats, error, status,
// disconnected, message (a server message the viewer leaves to the page), step (each animation
// frame, after the camera moved), vr (a VR session started or ended: xr.js).

import { OrbitCamera } from './camera.js';
import { Connection, ERROR_INVALID_ARGUMENT, ERROR_SERVER_FULL, ERROR_SHUTTING_DOWN, ERROR_UNAUTHORIZED } from './connection.js';
import { Controls } from './controls.js';
import { CODEC_H264, decodableCodecs, hasWebCodecs, StreamDecoder } from './decoder.js';
import { DepthProbes } from './depth_probes.js';
import { depthAt } from './depth_warp.js';
import { ViewDisplay } from './display.js';
import { PageBusy } from './page_busy.js';
import { PathPlayer } from './path_player.js';
import { TOUR_SECONDS_PER_VIEW } from './paths.js';
import { playbackOf, resolvePose } from './pose_input.js';
import { loadProtocol } from './protocol.js';
import { planeDepthFor } from './reproject.js';
import { capViewport, parseMaxSize } from './viewport.js';
import { VrSession } from './xr.js';

export const VIEWER_EVENTS = ['connected', 'frame', 'stats', 'error', 'status', 'disconnected', 'message', 'step', 'vr'];

// Where this module was loaded from: the schema and the protobufjs runtime lie beside it, also
// when another site's page imports it.
const MODULE_BASE = new URL('.', import.meta.url).href;

// ws(s)://<the page's host>/ws: the server that served the page.
export function pageWebSocketUrl(loc = location) {
  return `${loc.protocol === 'https:' ? 'wss:' : 'ws:'}//${loc.host}/ws`;
}

// The protobufjs runtime (the global `protobuf`): the page's own (index.html loads it) or,
// on another site's page, vendor/protobuf.min.js from beside this module, loaded once. A classic
// script: it needs no CORS.
let protobufLoading = null;
function protobufRuntime(base) {
  if (globalThis.protobuf) return Promise.resolve(globalThis.protobuf);
  protobufLoading = protobufLoading || new Promise((resolve, reject) => {
    const s = document.createElement('script');
    s.src = new URL('vendor/protobuf.min.js', base).href;
    s.onload = () => (globalThis.protobuf ? resolve(globalThis.protobuf) : reject(new Error(`${s.src} defined no protobuf`)));
    s.onerror = () => reject(new Error(`cannot load ${s.src}`));
    document.head.append(s);
  });
  return protobufLoading;
}

// A canvas for the view and one for the edge fill under it, in `container` (a box of any size).
function makeCanvases(container) {
  const box = document.createElement('div');
  box.style.cssText = 'position:relative;overflow:hidden;width:100%;height:100%;isolation:isolate;background:#000';
  const backdrop = document.createElement('canvas');
  backdrop.style.cssText = 'position:absolute;inset:0;width:100%;height:100%;pointer-events:none';
  backdrop.hidden = true;
  const canvas = document.createElement('canvas');
  canvas.tabIndex = 0;
  canvas.style.cssText = 'display:block;position:relative;width:100%;height:100%;touch-action:none;outline:none;' +
    'transform-origin:0 0;cursor:grab';
  box.append(backdrop, canvas);
  container.append(box);
  return { canvas, backdrop };
}

export class CatgsViewer extends EventTarget {
  // options: README.md "CatgsViewer".
  constructor(options = {}) {
    super();
    const o = options;
    const made = o.canvas ? null : makeCanvases(o.container || document.body);
    this.canvas = o.canvas || made.canvas;
    this.display = new ViewDisplay(this.canvas, made ? made.backdrop : o.backdrop || null);
    this.server = o.server || pageWebSocketUrl();
    this.scene = String(o.scene || '').slice(0, 128);
    this.token = o.token || '';
    this.codec = o.codec || '';
    this.renderScale = Math.min(Math.max(Number(o.scale) || 1, 0.1), 4);
    this.maxSize = typeof o.maxSize === 'object' && o.maxSize ? o.maxSize : parseMaxSize(o.maxSize);
    this.reprojectOn = o.reproject !== false;
    this.controlsOn = o.controls !== false;
    this.keyTarget = o.keyTarget || this.canvas;
    this.assetBase = o.assetBase || MODULE_BASE;
    // Hooks for a page built on the viewer: driveCamera(dt, now, controls) moves the camera
    // instead of the controls (walk mode); reprojectDepth(camera) -> the scene's depth ahead
    // (null: the orbit target's plane).
    this.driveCamera = null;
    this.reprojectDepth = null;
    // In VR: driveVr({ head, up, stick, delta, dt, now }) -> the world step to take instead of
    // `delta` (the thumbstick's free step), or null to take it (xr.js).
    this.driveVr = null;
    this._initState();
  }

  // The session's state, before any connection.
  _initState() {
    this.protocol = null;
    this.connection = null;
    this.decoder = null;
    this.controls = null;
    this.camera = null;
    this.codecs = [];
    this._welcome = null; // the Welcome message
    this.sessionOpen = false;
    this.viewport = null;
    this.poseSequence = 0;
    this.sentVersion = -1;
    this.sentPoses = new Map(); // sequence -> the pose sent, until a frame answers it or a later one
    this.shownPose = null; // the pose of the frame on the canvas (null: unknown, not re-projected)
    this.reprojectVersion = -1; // the camera version the canvas transform was worked out for
    this.framesDecoded = 0;
    this.sessionFrames = 0;
    this.lastFrame = null;
    this.depthGrid = null; // the shown frame's depth grid (depth_warp.js), once inflated
    this.depthGridSequence = -1;
    this.lastPoseSent = null;
    this.reconnectAt = 0;
    this.drainEndsAt = 0; // performance.now() when a draining server ends this session (0: none)
    this.status = 'starting';
    this.startError = ''; // why the viewer could not start (status 'unsupported' or 'error')
    this.loadProgress = null; // the last LoadProgress (the scene loading for this session)
    this.closeInfo = null; // the last onClose argument while not connected
    this.maxBitrateKbps = 0; // the bitrate ceiling (0: the server's default); sent as Quality
    this.unreportedLatencyMs = 0; // the newest shown frame's pose-to-frame latency, for the next Pose
    this.receipt = null; // { sequence, receivedMs }: the newest frame's arrival, for the next Pose
    this.probes = new DepthProbes((bytes) => this.send(bytes), () => this.protocol);
    this.player = new PathPlayer();
    this.rttMs = null;
    this.lastPingMs = -Infinity;
    this.lastStepMs = performance.now();
    this.busy = new PageBusy();
    this.abort = new AbortController(); // every listener and timer of this viewer ends with it
    this.started = null;
    this.vr = null; // the VrSession (xr.js) while the headset shows the stream
  }

  // ---- what a page reads ----

  get connected() {
    return this.sessionOpen;
  }

  // The Welcome as a plain object (field names as in the .proto, every field), or null.
  get welcome() {
    return this._welcome && this.protocol ? this._plain('Welcome', this._welcome) : null;
  }

  get decoderErrors() {
    return this.decoder ? this.decoder.errors : 0;
  }

  get playing() {
    return this.player.kind;
  }

  pose() {
    return this.camera ? this.camera.pose() : null;
  }

  // The canvas as a PNG data URL: exactly the decoded pixels.
  snapshot() {
    return this.canvas.toDataURL('image/png');
  }

  _plain(type, msg) {
    return this.protocol.root.lookupType(`catgs.stream.v1.${type}`).toObject(msg, { defaults: true });
  }

  _emit(type, detail) {
    this.dispatchEvent(new CustomEvent(type, { detail }));
  }

  _setStatus(status) {
    this.status = status;
    this._emit('status', { status });
  }

  // ---- start and stop ----

  // Loads the schema, checks the decoder and opens the connection; resolves true once started,
  // false when this browser or server cannot (status 'unsupported' or 'error', an `error` event).
  start() {
    this.started = this.started || this._start();
    return this.started;
  }

  async _start() {
    this.busy.start();
    this.viewport = this._viewportSize();
    this.canvas.width = this.viewport.width;
    this.canvas.height = this.viewport.height;
    if (!hasWebCodecs()) {
      return this._fail('unsupported', 'This browser cannot decode H.264 with WebCodecs (VideoDecoder is missing). ' +
        'Use a recent Chromium, Edge or Chrome over https or localhost.');
    }
    try {
      this.protocol = await loadProtocol(await protobufRuntime(this.assetBase), this.assetBase);
    } catch (e) {
      return this._fail('error', `cannot start: ${e.message}`);
    }
    // The server would refuse the WebSocket of a page of this origin (403 at the handshake, which
    // a page cannot read): say so rather than retrying as if the server were away.
    if (this.protocol.sessionOriginRefused) {
      return this._fail('origin-refused', `this site (${location.origin}) may not show streams from this server; ` +
        'its operator can allow it (--allowed-origins)');
    }
    this.codecs = this.codec === 'h264' ? [CODEC_H264] : await decodableCodecs();
    if (this.abort.signal.aborted) return false; // closed meanwhile
    this.decoder = new StreamDecoder({
      onFrame: (frame, meta) => this._drawFrame(frame, meta),
      onError: (e) => this._decoderError(e),
      requestKeyFrame: () => this.requestKeyFrame(),
    });
    this._wireInput();
    this.connection = new Connection(this.server, this.protocol, {
      onOpen: () => this._onOpen(),
      onMessage: (kind, msg) => this._onMessage(kind, msg),
      onClose: (info) => this._onClose(info),
      onProtocolError: (e) => console.warn('catgs: bad message from the server:', e),
    });
    this._startTimers();
    this._setStatus('connecting');
    this.connection.connect();
    return true;
  }

  _fail(status, reason) {
    this.startError = reason;
    this._setStatus(status);
    const name = { unsupported: 'UNSUPPORTED', 'origin-refused': 'ORIGIN_REFUSED' }[status] || 'STARTUP';
    this._emit('error', { name, code: 0, reason, permanent: true, status });
    return false;
  }

  _wireInput() {
    const signal = this.abort.signal;
    if (this.controlsOn) {
      const page = this.keyTarget === window;
      this.controls = new Controls(this.canvas, () => this.camera,
        { keyTarget: this.keyTarget, wheelOverPage: page, focusOnPointer: !page, signal });
      // Touching the view takes it back from a playing path.
      this.canvas.addEventListener('pointerdown', () => this.stopPath(), { signal });
    }
    // One Resize per gesture, not one per pixel: the window (device pixel ratio too) or the box.
    let timer = null;
    const later = () => {
      clearTimeout(timer);
      timer = setTimeout(() => this._onResize(), 150);
    };
    window.addEventListener('resize', later, { signal });
    const observer = new ResizeObserver(later);
    observer.observe(this.canvas);
    signal.addEventListener('abort', () => {
      observer.disconnect();
      clearTimeout(timer);
    });
  }

  _startTimers() {
    const signal = this.abort.signal;
    const every = (ms, fn) => {
      const id = setInterval(fn, ms);
      signal.addEventListener('abort', () => clearInterval(id));
    };
    every(2000, () => this._keepAlive());
    // requestAnimationFrame stops in hidden tabs; a slow timer keeps poses and the page going.
    every(100, () => {
      const now = performance.now();
      if (now - this.lastStepMs > 250) this._step(now);
    });
    const loop = (now) => {
      if (signal.aborted) return;
      this._step(now);
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  // Ends the session and everything the viewer runs (listeners, timers); the canvas stays.
  close() {
    if (this.vr) this.vr.end();
    this.abort.abort();
    this.busy.stop();
    if (this.connection) this.connection.close();
    if (this.decoder) this.decoder.reset();
    this.player.stop();
    this.probes.rejectAll();
    this.sessionOpen = false;
  }

  // ---- the connection ----

  _onOpen() {
    this._setStatus('handshake');
    this._onResize(); // the box may have changed while disconnected
    const v = this.viewport;
    this.send(this.protocol.encodeHello({
      width: v.width, height: v.height, token: this.token, scene: this.scene, loadProgress: true, codecs: this.codecs,
    }));
  }

  // Another access token: the connection starts again with it (after a refusal too).
  setToken(token) {
    this.token = String(token || '');
    if (!this.connection) return;
    this._setStatus('connecting');
    this.connection.restart();
  }

  // Skips the wait before the next reconnect attempt.
  retryNow() {
    if (this.connection) this.connection.retryNow();
  }

  send(bytes) {
    return this.connection ? this.connection.send(bytes) : false;
  }

  _onMessage(kind, msg) {
    switch (kind) {
      case 'welcome':
        this._onWelcome(msg);
        break;
      case 'frame':
        this._onFrameMessage(msg);
        break;
      case 'stats':
        // A draining server (SIGTERM) says when it ends this session: the words count it down.
        this.drainEndsAt = msg.drain_ms_left > 0 ? performance.now() + msg.drain_ms_left : 0;
        this._emit('stats', { server: this._plain('Stats', msg), rttMs: this.rttMs, framesDecoded: this.framesDecoded });
        this._keepAlive(); // message events still run when a hidden tab's timers are throttled
        break;
      case 'error':
        // Told when the connection closes, with what happens next (_onClose).
        console.warn(`catgs: server error ${this.protocol.errorCodeName(msg.code)}: ${msg.reason}` +
          (msg.retry_after_ms ? ` (retry after ${msg.retry_after_ms} ms)` : ''));
        break;
      case 'pong':
        this.rttMs = performance.now() - msg.client_time_ms;
        break;
      case 'load_progress':
        this.loadProgress = msg;
        this._setStatus('loading-scene');
        break;
      case 'depth_result':
        // A plain object with every field (proto3 leaves zeros out: opacity 0, no hit).
        this.probes.answer(msg, this._plain('DepthResult', msg));
        break;
      default:
        this._emit('message', { kind, msg }); // annotations, export_progress, export_chunk: the page's
        break;
    }
  }

  _onWelcome(w) {
    this._welcome = w;
    this.sessionOpen = true;
    this.sessionFrames = 0;
    this.closeInfo = null;
    this.poseSequence = 0; // the initial pose is sequence 0; ours count from 1
    this.sentPoses = new Map();
    this.shownPose = null;
    this.display.clearTransform();
    this.connection.markHealthy();
    this.decoder.reset();
    this.decoder.setWelcomeCodec(w.codec);
    // Keep the user's view across a reconnect to the same scene; start fresh otherwise.
    const newView = !this.camera || this.camera.sceneName !== w.scene_name;
    if (newView) {
      this.camera = OrbitCamera.fromWelcome(w.initial_pose, w.scene_bounds, w);
      this.camera.sceneName = w.scene_name;
    }
    this._setStatus('first-view');
    // Answers of the last session never come: their waits end.
    this.probes.rejectAll();
    // A chosen ceiling outlives reconnects; the default is never sent (older servers lack Quality).
    if (this.maxBitrateKbps > 0) this.send(this.protocol.encodeQuality(this.maxBitrateKbps));
    this.sentVersion = -1;
    // Before the first pose: a view set in a handler (setPose) is the first one rendered.
    this._emit('connected', { welcome: this.welcome, newView });
    if (this.vr) this.vr.resend(); // in VR the XR loop's next pose is the first
    else if (this.camera.version !== this.sentVersion) this._sendPose();
  }

  _onClose(info) {
    const { code, reason, retryInMs, error, permanent, reached } = info;
    this.sessionOpen = false;
    this.receipt = null; // the next session's frames are numbered anew
    this.rttMs = null;
    this.probes.rejectAll();
    this.closeInfo = info;
    this.decoder.reset();
    this.reconnectAt = performance.now() + (retryInMs || 0);
    this.drainEndsAt = 0;
    // A restarting server's later attempts say "restarting" still (closeStatus says "stopping").
    const status = info.stopping && !error && this.status === 'restarting' ? 'restarting' : closeStatus(info);
    const was = this.status;
    this._emit('disconnected', { code, reason, error, permanent, retryInMs, reached, status });
    this._setStatus(status);
    if (error) {
      const name = this.protocol.errorCodeName(error.code);
      this._emit('error', { name, code: error.code, reason: error.reason || '', permanent: !!permanent, retryInMs, status });
    } else if ((status === 'unreachable' || status === 'disconnected') && was !== status) {
      // No server to say why (never reached, or the connection dropped): an error all the same,
      // so a host page that listens to `error` alone learns it has no stream. Once an outage: the
      // retries that follow fail alike.
      const lost = status === 'disconnected';
      this._emit('error', {
        name: lost ? 'CONNECTION_LOST' : 'UNREACHABLE',
        code: 0,
        reason: lost ? 'the connection to the server was lost' : 'cannot reach the server',
        permanent: false,
        retryInMs,
        status,
      });
    }
    console.info(`catgs: connection closed (${code}${reason ? `: ${reason}` : ''})` +
      (permanent ? ', not retrying' : `, retry in ${retryInMs} ms`));
  }

  // A Ping every 2 s at most: the round-trip time, and proof of life for the server, which ends a
  // session silent for --silent-timeout-ms (60 s by default). Called from a timer and from each
  // Stats message (about one a second), because browsers throttle a hidden tab's timers to once a
  // minute after a while.
  _keepAlive() {
    const now = performance.now();
    if (!this.sessionOpen || now - this.lastPingMs < 1900) return;
    this.lastPingMs = now;
    this.send(this.protocol.encodePing(now));
  }

  // ---- the stream's size ----

  _viewportSize() {
    const dpr = (window.devicePixelRatio || 1) * this.renderScale;
    const c = this.canvas;
    return capViewport((c.clientWidth || window.innerWidth) * dpr, (c.clientHeight || window.innerHeight) * dpr, this.maxSize);
  }

  _onResize() {
    if (this.vr) return; // the headset's eyes size the stream (_vrResize)
    const v = this._viewportSize();
    if (this.viewport && v.width === this.viewport.width && v.height === this.viewport.height) return;
    this.viewport = v;
    if (this.sessionOpen && this.send(this.protocol.encodeResize(v.width, v.height))) this._resendPose();
  }

  // The stream at a fraction of the device resolution (cheaper on a CPU renderer or a slow link).
  setRenderScale(scale) {
    this.renderScale = Math.min(Math.max(Number(scale) || 1, 0.1), 4);
    this._onResize();
  }

  // A bitrate ceiling, kbit/s (0: the server's default). The encoder restarts with it (an IDR
  // follows); the current pose again makes that frame.
  setMaxBitrate(kbps) {
    this.maxBitrateKbps = kbps;
    if (this.sessionOpen && this.send(this.protocol.encodeQuality(kbps))) this._resendPose();
  }

  // ---- poses ----

  // setPose({ position, orientation | rotation | lookAt, up, fovDeg }) (pose_input.js): the
  // camera moves there and the pose goes out at once. Returns its sequence (null when it could
  // not be sent). A playing path moves the camera on (stopPath() first).
  setPose(spec) {
    const cam = this.camera;
    if (!cam) throw new Error('no session yet');
    const p = resolvePose(spec, { ...cam.pose(), up: cam.up });
    cam.setPose(p.position, p.orientation, p.fovDeg);
    if (p.target) cam.target = p.target; // orbiting turns around the point looked at
    return this._sendPose();
  }

  _sendPose() {
    const cam = this.camera;
    if (!cam || !this.sessionOpen) return null;
    const sequence = this._sendPoseMessage(cam.pose());
    if (sequence !== null) this.sentVersion = cam.version;
    return sequence;
  }

  // Sends `pose` ({ position, orientation, fovDeg }) and, in VR, both eyes (`eyes`: { left, right }
  // as stereo.js eyeViewOf makes them) and the headset's display rate (Hz, 0: unknown) as one
  // Pose; returns its sequence, or null when not sent.
  _sendPoseMessage(pose, eyes = null, displayHz = 0) {
    if (!this.sessionOpen) return null;
    // Poses are tiny; a large send buffer means the link is stalled, and the newest pose will go
    // out once it drains (latest wins anyway).
    if (this.connection.bufferedAmount > 256 * 1024) return null;
    const sequence = ++this.poseSequence;
    const clientTimeMs = performance.now();
    // The newest shown frame's latency rides along to the server's /metrics (end to end).
    const shownLatencyMs = this.unreportedLatencyMs;
    // And the newest frame's arrival: the server's rate controller reads the queue on the link
    // from these receipts (server/session/link_rate.h).
    const receipt = this.receipt || { sequence: 0, receivedMs: 0 };
    const stereo = eyes ? { leftEye: eyes.left, rightEye: eyes.right } : {};
    if (!this.send(this.protocol.encodePose({ sequence, clientTimeMs, shownLatencyMs, receipt, ...pose, ...stereo, displayHz }))) return null;
    this.unreportedLatencyMs = 0;
    this.receipt = null;
    this.sentPoses.set(sequence, { position: pose.position, orientation: pose.orientation, fovDeg: pose.fovDeg });
    this.lastPoseSent = {
      sequence, clientTimeMs, position: pose.position, orientation: pose.orientation, fovDeg: pose.fovDeg,
      leftEye: eyes ? eyes.left : null, rightEye: eyes ? eyes.right : null, displayHz,
    };
    return sequence;
  }

  // The server renders only when a pose arrives (a KeyFrameRequest or Resize just marks the next
  // frame as an IDR), so both are followed by the current pose again, even if the camera is still.
  _resendPose() {
    if (this.vr) {
      this.vr.resend(); // the XR loop owns the poses: its next one goes out
      return null;
    }
    this.sentVersion = -1;
    return this._sendPose();
  }

  // Asks for an IDR and sends the current pose again; returns that pose's sequence.
  // The session's annotations document (SaveAnnotations, `json` its text; an author's or admin's
  // session: the server refuses others'): false when not connected.
  saveAnnotations(json) {
    return this.connected && this.send(this.protocol.encodeSaveAnnotations(json));
  }

  // Asks the server to render `request` to a video (ExportVideoRequest: { exportId, path (the
  // poses as floats, paths.js pathFloats), width, height, fps, pipeline }); its ExportProgress and
  // ExportChunk messages come as `message` events. false when not connected.
  exportVideo(request) {
    return this.connected && this.send(this.protocol.encodeExportVideo(request));
  }

  // Cancels export `exportId` (ExportCancel); false when not connected.
  cancelExport(exportId) {
    return this.connected && this.send(this.protocol.encodeExportCancel(exportId));
  }

  requestKeyFrame() {
    if (!this.sessionOpen) return null;
    this.send(this.protocol.encodeKeyFrameRequest());
    return this._resendPose();
  }

  // Back to the server's first view of the scene (a new camera version: the loop sends it).
  resetView() {
    const w = this._welcome;
    if (!w) return false;
    this.stopPath();
    const name = this.camera ? this.camera.sceneName : w.scene_name;
    const version = this.camera ? this.camera.version + 1 : 0;
    this.camera = OrbitCamera.fromWelcome(w.initial_pose, w.scene_bounds, w);
    this.camera.sceneName = name;
    this.camera.version = version;
    return true;
  }

  // ---- frames ----

  _onFrameMessage(msg) {
    if (!this.sessionOpen) return;
    // A receipt tells the server's rate controller when the frame arrived; read after the page's
    // thread was busy, it would say when the thread came back (page_busy.js): none for such a frame.
    if (!this.busy.recently()) this.receipt = { sequence: msg.sequence, receivedMs: performance.now() };
    this.decoder.decode(msg);
  }

  _drawFrame(frame, meta) {
    try {
      // In VR the headset shows the frame (xr.js); the page's canvas keeps its last flat frame.
      const vr = this.vr;
      if (vr) vr.takeFrame(frame, meta, meta ? this.sentPoses.get(meta.poseSequence) || null : null);
      const { width, height } = vr ? { width: frame.displayWidth, height: frame.displayHeight } : this.display.draw(frame);
      if (vr && meta) {
        for (const k of this.sentPoses.keys()) if (k < meta.poseSequence) this.sentPoses.delete(k);
      } else if (meta) {
        // The frame's pose: where the server predicted the camera would be (Frame.shown_pose), else
        // the pose it answers; the re-projection starts from it.
        this.shownPose = meta.shownPose || this.sentPoses.get(meta.poseSequence) || null;
        for (const k of this.sentPoses.keys()) if (k < meta.poseSequence) this.sentPoses.delete(k);
        this._takeDepthGrid(meta);
      }
      if (!vr) this._updateReprojection();
      const now = performance.now();
      this.framesDecoded++;
      this.sessionFrames++;
      if (this.status === 'first-view') this._setStatus('streaming');
      const latency = meta ? now - meta.clientTimeMs : NaN;
      if (latency >= 0 && latency <= 3.6e6) this.unreportedLatencyMs = latency;
      this.lastFrame = {
        poseSequence: meta ? meta.poseSequence : -1,
        sequence: meta ? meta.sequence : -1,
        width,
        height,
        keyFrame: meta ? meta.keyFrame : false,
        latencyMs: latency,
        // A headset's frame (issue 94): an eye's width (0: mono) and the eyes it shows.
        eyeWidth: meta ? meta.eyeWidth : 0,
        leftEye: meta ? meta.leftEye : null,
        rightEye: meta ? meta.rightEye : null,
      };
      this._emit('frame', { ...this.lastFrame, codec: this.decoder.codec, framesDecoded: this.framesDecoded, timeMs: now });
    } finally {
      frame.close(); // VideoFrames hold decoder memory until closed
    }
  }

  // The frame's depth grid (decoder.js inflates it while the frame decodes): at once where it is
  // there, else once it is (a few ms), if the frame is still the one shown.
  _takeDepthGrid(meta) {
    this.depthGrid = meta.depthGridReady;
    this.depthGridSequence = meta.sequence;
    if (this.depthGrid) {
      this.display.setDepthGrid(this.depthGrid);
      return;
    }
    if (!meta.depthGrid) return;
    meta.depthGrid.then(
      (grid) => {
        if (this.depthGridSequence !== meta.sequence || !this.sessionOpen) return;
        this.depthGrid = grid;
        this.display.setDepthGrid(grid);
        this._updateReprojection();
      },
      (e) => console.warn('catgs: a frame\'s depth grid is malformed:', e),
    );
  }

  // The scene's depth (world units along the shown frame's forward axis) under CSS pixel (x, y) of
  // the canvas as the frame was drawn (not re-projected), from the frame's depth grid: no round
  // trip. null where the frame has no grid (yet) or no surface there.
  frameDepthAt(x, y) {
    const g = this.depthGrid;
    const c = this.canvas;
    if (!g || !c.clientWidth || !c.clientHeight) return null;
    return depthAt(g, c.width, c.height, (x * c.width) / c.clientWidth, (y * c.height) / c.clientHeight);
  }

  _decoderError(e) {
    console.warn('catgs: decoder error, requesting a key frame:', e);
    this._emit('error', { name: 'DECODER', code: 0, reason: String((e && e.message) || e), permanent: false, status: this.status });
  }

  // The shown frame re-projected from its pose to the camera's (display.js).
  _updateReprojection() {
    const cam = this.camera;
    this.reprojectVersion = cam ? cam.version : -1;
    const depthOf = () => (this.reprojectDepth && this.reprojectDepth(cam)) || planeDepthFor(this.shownPose, cam.target, cam.sceneScale);
    this.display.reproject(this.reprojectOn && cam ? this.shownPose : null, cam ? cam.pose() : null, depthOf);
  }

  // ---- depth under a pixel (DepthRequest -> DepthResult) ----

  // What lies under pixel (x, y) of a width x height view of `pose` (the server's depth probe).
  // Resolves with the DepthResult as a plain object (hit, point, depth, opacity, error); rejects
  // when not connected or the session ends first.
  probePose(pose, width, height, x, y) {
    if (!this.sessionOpen) return Promise.reject(new Error('not connected'));
    return this.probes.request(pose, width, height, x, y);
  }

  // What lies under CSS pixel (x, y) of the canvas, as the camera sees it now (the shown frame is
  // re-projected to this pose): the view is the canvas's CSS box, which has the stream's aspect.
  probe(x, y) {
    const cam = this.camera;
    if (!cam) return Promise.reject(new Error('no view yet'));
    const w = Math.max(1, Math.round(this.canvas.clientWidth || window.innerWidth));
    const h = Math.max(1, Math.round(this.canvas.clientHeight || window.innerHeight));
    return this.probePose(cam.pose(), w, h, x, y);
  }

  // ---- VR (issue 94) ----

  // Starts an immersive VR session (xr.js; call it from a click: a headset wants a user gesture)
  // on this session's camera: the headset's first pose is the camera's. options: unitsPerMetre
  // (world units in a metre; default 1, the scene's unit taken as a metre), planeDepth (xr.js).
  // Resolves once the session runs (a `vr` event with active true); rejects before a session, in
  // VR already, or when the browser refuses (no WebXR, no headset, no WebGL2).
  async enterVr(options = {}) {
    if (!this.camera || !this.sessionOpen) throw new Error('no session yet');
    if (this.vr) throw new Error('already in VR');
    this.stopPath();
    const vr = new VrSession(this, options);
    await vr.start();
    this.vr = vr;
    this._emit('vr', { active: true });
    return true;
  }

  // Ends the VR session; resolves with the head's last pose once the page streams its own view
  // again (null when not in VR).
  exitVr() {
    return this.vr ? this.vr.end() : Promise.resolve(null);
  }

  // The headset's stream size (xr.js: both eyes side by side).
  _vrResize({ width, height }) {
    this.viewport = { width, height };
    if (this.sessionOpen) this.send(this.protocol.encodeResize(width, height));
  }

  // The session ended (the headset, or exitVr): the camera takes the head's last pose (its
  // position and orientation; the page's field of view stays), and the stream its page size again.
  _vrEnded(vr, head) {
    if (this.vr !== vr) return;
    this.vr = null;
    const cam = this.camera;
    if (head && cam) cam.setPose(head.position, head.orientation, cam.fovDeg);
    this.viewport = null;
    this._onResize(); // Resize to the page's size and the camera's pose again
    this._emit('vr', { active: false, pose: cam ? cam.pose() : null });
  }

  // ---- paths ----

  // Plays `path` (pose_input.js playbackOf: timed samples, tour waypoints (each what setPose
  // takes), or a cameras.json or .trace file's text). options: kind (what `playing` says;
  // 'path'), secondsPerView (a tour's pace; 2 s), onWaypoint(index, waypoint) (a tour reached a
  // waypoint). Resolves true when it played to the end, false when stopped (stopPath, another
  // path, a touch of the view); rejects before any session or for a path it cannot read.
  playPath(path, { kind = 'path', secondsPerView = TOUR_SECONDS_PER_VIEW, onWaypoint = null } = {}) {
    if (!this.camera) return Promise.reject(new Error('no session yet'));
    let playback;
    try {
      playback = playbackOf(path, secondsPerView, { ...this.camera.pose(), up: this.camera.up });
    } catch (e) {
      return Promise.reject(e);
    }
    return this.player.play(playback, { kind, secondsPerView, onWaypoint });
  }

  stopPath() {
    this.player.stop();
  }

  // ---- the loop ----

  // One step: a playing path, the page's driver (walk mode) or the controls move the camera; the
  // pose goes out if it moved, the shown frame follows it; then the page's own step.
  _step(now) {
    const dt = (now - this.lastStepMs) / 1000;
    this.lastStepMs = now;
    const cam = this.camera;
    if (this.vr) {
      // The XR loop owns the poses (xr.js); the page's own step still runs.
      this._emit('step', { now, dt });
      return;
    }
    if (this.player.current && cam) this.player.step(now, cam);
    else if (this.driveCamera) this.driveCamera(dt, now, this.controls);
    else if (this.controls) this.controls.update(dt);
    if (cam && cam.version !== this.sentVersion) this._sendPose();
    if (cam && cam.version !== this.reprojectVersion) this._updateReprojection();
    this._emit('step', { now, dt });
  }
}

// The status a closed connection leaves (README.md "States").
function closeStatus({ error, permanent, reached, stopping }) {
  // A scene the server does not have (session.cpp: "no scene 'X' on this server").
  if (permanent && error && error.code === ERROR_INVALID_ARGUMENT && /^no scene '/.test(error.reason || '')) return 'no-scene';
  if (permanent) return error && error.code === ERROR_UNAUTHORIZED ? 'needs-token' : 'refused';
  if (error && error.code === ERROR_SERVER_FULL) return 'server-full';
  // A server stopping (SIGTERM, SIGINT) cannot tell whether it comes back: "restarting" only when
  // its reason says so.
  if (error && error.code === ERROR_SHUTTING_DOWN) return /restart/i.test(error.reason || '') ? 'restarting' : 'stopping';
  // The attempts after it that find the server gone (Connection's `stopping`): still stopping.
  if (stopping) return 'stopping';
  if (!reached) return 'unreachable';
  return 'disconnected';
}
