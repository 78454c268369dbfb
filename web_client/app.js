// CaT-GS Stream page: the full-window viewer with its toolbar, panels (paths, notes, quality,
// help), walk mode, video export, token field, scene picker, keys and stats, built on CatgsViewer
// (catgs_viewer.js), which owns the stream: connection, decoding, canvas, camera controls.
// Wiring only; the pieces live in the modules imported below.

import { CatgsViewer, defaultWebSocketUrl, parseMaxSize, vrSupported } from './viewer/viewer.js';
import { Overlay } from './overlay.js';
import {
  LOADGEN_SECONDS_PER_VIEW, PathRecorder, fromInriaCameras, fromTraceFile, resample, toInriaCameras,
  TOUR_SECONDS_PER_VIEW, toTraceFile,
} from './viewer/viewer.js';
import { NotesUi } from './notes_ui.js';
import { VrWalk, WalkMode } from './walk.js';
import { VideoExportUi, tourSamples } from './video_export.js';
import { parseView, viewUrl, withoutView } from './view_link.js';
import { TOKEN_KEY, takeToken } from './token.js';
import { ScenePicker } from './scene_picker.js';
import { makeTokenForm, stateMessage } from './state_words.js';
import { installTestHook } from './test_hook.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const overlay = new Overlay($('stats'), $('messages'), { showStats: params.get('stats') === '1', noticeEl: $('notice') });
const linkView = parseView(params);
// ?scene=NAME opens that scene of a server that serves several (GET /scenes lists them).
const sceneParam = (params.get('scene') || '').slice(0, 128);
const isTouch = (navigator.maxTouchPoints || 0) > 0 || matchMedia('(pointer: coarse)').matches;

// The stream: the page's own canvases, the keys of the whole window.
const viewer = new CatgsViewer({
  canvas: $('view'),
  backdrop: $('backdrop'),
  keyTarget: window,
  server: defaultWebSocketUrl(location), // beside the page, or ?ws=
  scene: sceneParam,
  token: takeToken(location, sessionStorage, history), // and gone from the address bar
  // ?codec=h264: offer only H.264 (the page otherwise offers AV1 too where WebCodecs decodes it).
  codec: params.get('codec') === 'h264' ? 'h264' : '',
  // ?scale=0.5 renders at half the device resolution (cheaper on a CPU renderer or a slow link);
  // the quality menu changes it.
  scale: params.get('scale'),
  // The stream is capped (default 1920x1080, either orientation) whatever the device pixel ratio:
  // a phone at DPR 3 would otherwise ask for 1170x2532. ?max=WxH moves the cap.
  maxSize: parseMaxSize(params.get('max')),
  // Latency hiding (reproject.js): ?reproject=0 turns it off.
  reproject: params.get('reproject') !== '0',
});
const canvas = viewer.canvas;
const scenePicker = new ScenePicker($('scene-picker'), sceneParam);

const state = {
  linkApplied: false, // the view in the address was applied (first Welcome only)
  recorder: null, // PathRecorder while recording
  recording: null, // the last finished recording (samples)
  waypoints: [],
  urlVersion: -1,
  urlPending: -1,
  urlSettleAt: 0,
  notes: null, // NotesUi: hotspots, measurement, scale
  walk: null, // WalkMode
  videoExport: null, // VideoExportUi: Export video in the Paths panel
  hintHiddenBeforeWalk: false,
};

// ---- the viewer's events ----

function onConnected({ welcome: w, newView }) {
  overlay.setSession(w);
  // Export video only where the server would take it (an author's or admin's session on a server
  // with export built in); a viewer's request would be refused anyway.
  $('export-controls').hidden = !w.can_export;
  scenePicker.welcomed(w.scene_name);
  if (!newView) return; // a reconnect to the same scene keeps the user's view
  if (linkView && linkView.pose && !state.linkApplied) {
    state.linkApplied = true;
    const p = linkView.pose;
    if (linkView.scene && linkView.scene !== w.scene_name) {
      notice(`this link shows a view of "${linkView.scene}"; this server shows "${w.scene_name}": starting from its view`, 'warn', 6000);
    } else {
      viewer.camera.setPose(p.position, p.orientation, p.fovDeg ?? viewer.camera.fovDeg);
    }
  }
  state.urlVersion = viewer.camera.version;
}

function onDisconnected() {
  state.videoExport.onClosed();
  overlay.clearSession();
}

function onStats({ server: s }) {
  overlay.setServerStats(s); // a draining server's countdown: the state line (status_text.js)
}

function onViewerError({ name, reason }) {
  if (name !== 'DECODER') return; // the others: the state line (stateMessage)
  overlay.showMessage('decoder', `decoder error (${reason}); waiting for a key frame`, 'warn');
  setTimeout(() => overlay.clearMessage('decoder'), 3000);
}

// Server messages of the page's own features.
function onMessage({ kind, msg }) {
  if (kind === 'annotations') state.notes.onAnnotations(msg);
  else if (kind === 'export_progress') state.videoExport.onProgress(msg);
  else if (kind === 'export_chunk') state.videoExport.onChunk(msg);
}

// After each step of the viewer (the camera moved, the pose went out): the markers follow the
// view, a recording takes the pose; four times a second the words and the address bar.
let lastOverlayMs = 0;
function onStep({ now }) {
  state.notes.update();
  const cam = viewer.camera;
  if (state.recorder && cam) state.recorder.add(now, cam.pose());
  if (now - lastOverlayMs > 250) {
    lastOverlayMs = now;
    overlay.setRtt(viewer.rttMs);
    overlay.render(now);
    updateStateMessage();
    qualityStatus();
    syncUrl(now);
    if (state.recorder) pathsStatus();
  }
}

// ---- connection state, in words ----

const retryButton = [{ id: 'retry', label: 'retry now', onClick: () => viewer.retryNow() }];
let tokenForm = null;
const stateUi = {
  sceneParam,
  retry: retryButton,
  sceneChoice: () => scenePicker.choice(),
  tokenForm: () => (tokenForm = tokenForm || makeTokenForm(useToken)),
};

// A token typed into the field: this tab keeps it (shared links leave it out), and the viewer
// connects again with it.
function useToken(token) {
  sessionStorage.setItem(TOKEN_KEY, token);
  viewer.setToken(token);
}

function updateStateMessage() {
  const m = stateMessage(viewer, stateUi);
  if (m === null) overlay.clearMessage('state');
  else if (m) overlay.showMessage('state', m.text, m.level, m.actions);
}

// ---- notes ----

// Fly to `pose` over a second, as a tour of two views (the same interpolation).
function flyTo(pose) {
  if (!viewer.camera) return false;
  return playKeys('fly', [viewer.camera.pose(), pose], 0.5);
}

// The notes' share-link value in the address (viewUrl keeps it, the token never).
function notesLinkChanged() {
  const u = new URL(location.href);
  const v = state.notes.linkValue();
  if (v) u.searchParams.set('notes', v);
  else u.searchParams.delete('notes');
  history.replaceState(null, '', u.href);
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
  if (!viewer.resetView()) return;
  history.replaceState(null, '', withoutView(location.href));
  state.urlVersion = viewer.camera.version;
}

function shareUrl() {
  const cam = viewer.camera;
  return cam ? viewUrl(location.href, cam.pose(), cam.sceneName) : null;
}

async function copyLink() {
  const url = shareUrl();
  if (!url) return null;
  history.replaceState(null, '', url);
  state.urlVersion = viewer.camera.version;
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
  const cam = viewer.camera;
  if (!cam || viewer.playing || cam.version === state.urlVersion) return;
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
  viewer.setRenderScale(scale);
  qualityStatus();
}

function setMaxBitrate(kbps) {
  viewer.setMaxBitrate(kbps);
  qualityStatus();
}

function qualityStatus() {
  const v = viewer.viewport;
  const text = v ? `stream ${v.width}x${v.height}` : '';
  if ($('quality-status').textContent !== text) $('quality-status').textContent = text;
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
// the window. Again whenever the toolbar or the stats change size (wireMenu).
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
  const play = viewer.playing ? ` · playing ${viewer.playing}` : '';
  $('paths-status').textContent = `${rec} · ${state.waypoints.length} waypoint${state.waypoints.length === 1 ? '' : 's'}${play}`;
  $('btn-record').textContent = state.recorder ? 'Stop' : 'Record';
  $('btn-record').setAttribute('aria-pressed', String(!!state.recorder));
}

function toggleRecording() {
  if (state.recorder) {
    const r = state.recorder;
    state.recorder = null;
    if (r.samples.length) state.recording = r.samples;
  } else if (viewer.camera) {
    viewer.stopPath();
    state.recorder = new PathRecorder();
    state.recorder.add(performance.now(), viewer.camera.pose());
  }
  pathsStatus();
}

// The Paths panel's Play (the recorded path) and Play tour (the waypoints, 2 s apart).
function play(kind) {
  if (!viewer.camera) return false;
  if (state.recorder) toggleRecording();
  if (kind === 'tour' && state.waypoints.length >= 2) return playKeys('tour', state.waypoints.slice());
  if (kind !== 'path' || !state.recording || !state.recording.length) {
    notice(kind === 'tour' ? 'add at least 2 views for a tour' : 'record a path first', 'warn');
    return false;
  }
  return startPlayback(state.recording, { kind });
}

// Plays waypoints `keys` as a tour (secondsPerView apart). Waypoints of hotspots (`hotspot`: an
// id) show that hotspot's card as the tour reaches them.
function playKeys(kind, keys, secondsPerView = TOUR_SECONDS_PER_VIEW) {
  if (!viewer.camera || keys.length < 2) return false;
  if (state.recorder) toggleRecording();
  const onWaypoint = (k, key) => key.hotspot && state.notes.showCard(state.notes.hotspots.find((h) => h.id === key.hotspot));
  return startPlayback(keys, { kind, secondsPerView, onWaypoint });
}

// The viewer plays it; the panel says so until it ends (or a file's path cannot be played).
function startPlayback(path, options) {
  viewer.playPath(path, options).then(pathsStatus, (e) => notice(`cannot play: ${e.message}`, 'error', 5000));
  pathsStatus();
  return viewer.playing === options.kind;
}

// A hotspot tour: its waypoints become the tour (so tour.json exports them) and it plays.
function playHotspotTour(keys) {
  state.waypoints = keys;
  return playKeys('tour', keys);
}

function addWaypoint() {
  if (!viewer.camera) return 0;
  state.waypoints.push(viewer.camera.pose());
  pathsStatus();
  return state.waypoints.length;
}

function exportCameras(which) {
  const v = viewer.viewport;
  let poses;
  if (which === 'tour') poses = state.waypoints;
  // One view per LOADGEN_SECONDS_PER_VIEW: catgs-loadgen's cameras: replays it at recorded speed.
  else poses = state.recording ? resample(state.recording, LOADGEN_SECONDS_PER_VIEW) : [];
  if (poses.length < 2) return null; // the core's interpolation needs 2 views
  return JSON.stringify(toInriaCameras(poses, v.width, v.height, which === 'tour' ? 'tour' : 'path'), null, 1) + '\n';
}

function exportTrace() {
  const v = viewer.viewport;
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

// ---- keys ----

const KEY_ACTIONS = {
  r: () => resetView(),
  f: () => toggleFullscreen(),
  c: () => copyLink(),
  p: () => togglePanel('paths', 'btn-paths'),
  n: () => togglePanel('notes', 'btn-notes'),
  m: () => {
    togglePanel('notes', 'btn-notes', true);
    state.notes.setMode('measure');
  },
  g: () => toggleWalk(),
  h: () => togglePanel('helppanel', 'btn-help'),
  '?': () => togglePanel('helppanel', 'btn-help'),
  escape: () => {
    viewer.stopPath();
    // The new hotspot's form, or adding a hotspot or measuring, ends (the Notes panel comes
    // back); else every panel closes.
    if (!state.notes.escape()) togglePanel('paths', 'btn-paths', false);
  },
};

function onKey(e) {
  const t = e.target;
  // Keys typed into a field are its own, but Esc: it closes the form or panel the field is in.
  if (t && (t.tagName === 'INPUT' || t.tagName === 'TEXTAREA' || t.isContentEditable) && e.key !== 'Escape') return;
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  const key = e.key === 'Escape' ? 'escape' : e.key.length === 1 ? e.key.toLowerCase() : '';
  const action = Object.hasOwn(KEY_ACTIONS, key) ? KEY_ACTIONS[key] : null;
  if (!action) return;
  action();
  e.preventDefault();
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
  scenePicker.load();
  wireMenu();
  $('btn-fullscreen').addEventListener('click', toggleFullscreen);
  $('btn-help').addEventListener('click', () => togglePanel('helppanel', 'btn-help'));
  $('btn-paths').addEventListener('click', () => togglePanel('paths', 'btn-paths'));
  $('btn-quality').addEventListener('click', () => togglePanel('quality', 'btn-quality'));
  $('btn-notes').addEventListener('click', () => togglePanel('notes', 'btn-notes'));
  $('btn-walk').addEventListener('click', toggleWalk);
  $('btn-vr').addEventListener('click', toggleVr);
  // Shown only where the browser offers immersive VR (a headset, or an emulator).
  vrSupported().then((yes) => ($('btn-vr').hidden = !yes));
  wirePicking();
  wireQuality();
  wirePaths();
  window.addEventListener('keydown', onKey);
  // The hint has done its job once the view was moved (the help panel keeps the details).
  const hideHint = () => ($('hint').hidden = true);
  canvas.addEventListener('pointerdown', hideHint, { once: true });
  canvas.addEventListener('wheel', hideHint, { once: true, passive: true });
  pathsStatus();
}

// A click (no drag) on the scene picks a point while adding a hotspot or measuring.
function wirePicking() {
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
}

function wireQuality() {
  const scaleSelect = $('quality-scale');
  const scale = viewer.renderScale;
  if (![...scaleSelect.options].some((o) => Number(o.value) === scale)) {
    scaleSelect.add(new Option(`${Math.round(scale * 100)}% (?scale)`, String(scale)), 0);
  }
  scaleSelect.value = String(scale);
  scaleSelect.addEventListener('change', () => setRenderScale(Number(scaleSelect.value)));
  $('quality-bitrate').addEventListener('change', (e) => setMaxBitrate(Number(e.target.value)));
}

function wirePaths() {
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
}

// ---- VR (issue 94) ----

// Into the headset (from the button's click: a headset wants a user gesture), or out of it. The
// scene's scale, where Notes has one, makes a metre in the room a metre in the scene; walk mode,
// where it is on, checks each thumbstick step with its probes (walk.js VrWalk).
function toggleVr() {
  if (viewer.vr) return viewer.exitVr();
  const mpu = state.notes.metresPerUnit;
  viewer.driveVr = state.walk.on ? new VrWalk(state.walk).drive : null;
  return viewer.enterVr({ unitsPerMetre: mpu ? 1 / mpu : null }).catch((e) => {
    notice(`VR: ${e.message}`, 'error', 5000);
    return false;
  });
}

function onVr({ active }) {
  $('btn-vr').textContent = active ? 'Exit VR' : 'Enter VR';
  $('btn-vr').setAttribute('aria-pressed', String(active));
  if (!active) {
    viewer.driveVr = null;
    notice('back from VR at the headset\'s last view');
  }
}

function toggleWalk() {
  viewer.stopPath();
  const on = state.walk.toggle();
  // Walk mode moves the camera instead of the fly keys, and re-projects at what it sees ahead.
  viewer.driveCamera = on ? (dt, now, controls) => state.walk.update(dt, controls.keys, controls.shiftHeld, now) : null;
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

function makeFeatures() {
  state.notes = new NotesUi({
    camera: () => viewer.camera,
    probe: (x, y) => viewer.probe(x, y),
    notice,
    flyTo,
    playTour: playHotspotTour,
    save: (json) => viewer.saveAnnotations(json),
    linkChanged: notesLinkChanged,
    closePanel: () => togglePanel('notes', 'btn-notes', false),
    openPanel: () => togglePanel('notes', 'btn-notes', true),
    clearNotice: () => overlay.clearMessage('notice'),
  });
  state.notes.fromLink(params.get('notes'));
  state.walk = new WalkMode({
    camera: () => viewer.camera,
    probePose: (...a) => viewer.probePose(...a),
    metresPerUnit: () => state.notes.metresPerUnit,
    notice,
  }, isTouch ? $('walk-pad') : null); // the pad only where fingers walk; keys elsewhere
  viewer.reprojectDepth = (cam) => (state.walk.on ? state.walk.sceneDepth(cam) : null);
  state.videoExport = new VideoExportUi({
    exportVideo: (request) => viewer.exportVideo(request),
    cancelExport: (id) => viewer.cancelExport(id),
    // The recorded path, else the tour (the page's pace between views).
    samples: () => state.recording && state.recording.length >= 2
      ? state.recording
      : state.waypoints.length >= 2 ? tourSamples(state.waypoints, TOUR_SECONDS_PER_VIEW) : null,
    notice,
  });
}

function wireViewer() {
  viewer.addEventListener('connected', (e) => onConnected(e.detail));
  viewer.addEventListener('disconnected', onDisconnected);
  viewer.addEventListener('status', updateStateMessage);
  viewer.addEventListener('frame', (e) => {
    const f = e.detail;
    overlay.frameDrawn(f.timeMs, f.latencyMs, f.width, f.height, f.codec);
  });
  viewer.addEventListener('stats', (e) => onStats(e.detail));
  viewer.addEventListener('error', (e) => onViewerError(e.detail));
  viewer.addEventListener('message', (e) => onMessage(e.detail));
  viewer.addEventListener('step', (e) => onStep(e.detail));
  viewer.addEventListener('vr', (e) => onVr(e.detail));
}

async function main() {
  makeFeatures();
  installTestHook(viewer, {
    overlay, shareUrl, resetView, toggleRecording, addWaypoint, play, exportCameras, exportTrace, importText,
    setRenderScale, setMaxBitrate, toggleWalk, toggleVr,
    recording: () => state.recording,
    get notes() {
      return state.notes;
    },
    get walk() {
      return state.walk;
    },
    get videoExport() {
      return state.videoExport;
    },
  });
  wireUi();
  wireViewer();
  const starting = viewer.start(); // the stream's size is known from here
  qualityStatus();
  if (viewer.status !== 'unsupported' && linkView && linkView.error) {
    notice(`the view in this link was ignored: ${linkView.error}`, 'warn', 6000);
  }
  if (!(await starting)) overlay.render();
}

main();
