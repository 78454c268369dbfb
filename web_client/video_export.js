// "Export video" in the Paths panel (issue 38): the recorded path (or the tour) goes to the server
// as an ExportVideoRequest; the server renders it to an MP4 (server/session/video_export.h),
// reports ExportProgress (a bar with the time left here), and sends the file as ExportChunks,
// which become a Blob and a download link. The pure parts (the path on the wire, the bar's text,
// the chunks' assembly) are node-tested (tests/e2e/unit_web.mjs).

import { poseAtTime, tourDuration, tourPoseAt } from './viewer/viewer.js';

const $ = (id) => document.getElementById(id);

// One ExportVideoRequest must fit the server's 64 KiB message limit: 9 floats (36 bytes) a pose
// hold 1800 poses (the server's --export-max-poses default); a little room is left for the rest.
export const MAX_EXPORT_POSES = 1700;
// A tour is sampled this often for the request (the server interpolates between the samples).
export const TOUR_SAMPLE_SECONDS = 0.1;

// The poses of timed samples ({t, position, orientation, fovDeg}) as ExportVideoRequest.path: 9
// floats a pose (time_s, x y z, w x y z, fov). A path of more than maxPoses samples is sampled
// again, evenly on its clock, into maxPoses (first and last kept).
export function pathFloats(samples, maxPoses = MAX_EXPORT_POSES) {
  if (samples.length < 2) throw new Error('a video needs a path of at least 2 poses: record one first');
  let poses = samples;
  if (samples.length > maxPoses) {
    const t0 = samples[0].t;
    const span = samples[samples.length - 1].t - t0;
    poses = [];
    for (let k = 0; k < maxPoses; k++) {
      const t = t0 + (span * k) / (maxPoses - 1);
      poses.push({ t, ...poseAtTime(samples, t) });
    }
  }
  const out = new Float32Array(poses.length * 9);
  poses.forEach((p, k) => out.set([p.t, ...p.position, ...p.orientation, p.fovDeg], k * 9));
  return Array.from(out);
}

// A tour's waypoints as timed samples every TOUR_SAMPLE_SECONDS (the page's own tour playback).
export function tourSamples(keys, secondsPerView) {
  const end = tourDuration(keys, secondsPerView);
  const out = [];
  for (let t = 0; t < end; t += TOUR_SAMPLE_SECONDS) out.push({ t, ...tourPoseAt(keys, t, secondsPerView) });
  out.push({ t: end, ...tourPoseAt(keys, end, secondsPerView) });
  return out;
}

const clock = (s) => {
  const m = Math.floor(s / 60);
  const r = Math.round(s - 60 * m);
  return `${m}:${String(r).padStart(2, '0')}`;
};

// "8.2 kB", "12.5 MB".
export const sizeText = (bytes) => (bytes < 1e6 ? `${(bytes / 1e3).toFixed(1)} kB` : `${(bytes / 1e6).toFixed(1)} MB`);

// The bar's text for an ExportProgress.
export function progressText(p) {
  if (p.error) return `export failed: ${p.error}`;
  if (p.cancelled) return 'export cancelled';
  if (p.done) return `rendered ${p.frames_total} frames (${p.duration_s.toFixed(1)} s), downloading ${sizeText(p.bytes)}`;
  const left = p.frames_done > 0 ? `, ${clock(p.eta_ms / 1000)} left` : '';
  return `rendering ${p.frames_done}/${p.frames_total} frames${left}`;
}

// Joins ExportChunks in order into the file's bytes. add() throws on a chunk out of order.
export class ChunkAssembler {
  constructor(size) {
    this.size = size;
    this.parts = [];
    this.received = 0;
  }

  // Returns true when the file is complete.
  add(chunk) {
    if (chunk.offset !== this.received) throw new Error(`chunk at byte ${chunk.offset}, expected ${this.received}`);
    this.parts.push(chunk.data);
    this.received += chunk.data.length;
    if (this.received > this.size) throw new Error(`more bytes than the ${this.size} announced`);
    return chunk.last && this.received === this.size;
  }
}

// The panel's part: the button, the size and rate menus, the bar, Cancel and the link.
export class VideoExportUi {
  // app: { exportVideo(request) -> bool, cancelExport(id) -> bool (CatgsViewer's), samples() ->
  //        the path to export (timed samples) or null, notice(text, level, ms) }
  constructor(app) {
    this.app = app;
    this.nextId = 1;
    this.current = null; // { id, progress, assembler }
    this.last = null; // the last ExportProgress, for the test hook
    this.file = null; // { url, bytes, name } of the last file received
    this.others = new Map(); // id -> last ExportProgress of requests sent `alongside` (tests)
    $('btn-export-video').addEventListener('click', () => this.start());
    $('btn-export-cancel').addEventListener('click', () => this.cancel());
  }

  // Sends the request; returns its export id, or null (nothing to export, not connected, one
  // running). options: { size: 'WxH', fps, pipeline } instead of the menus; `alongside`: send it
  // even while one runs, without making it the panel's (the test of the server's own guard).
  start(options = {}) {
    if (this.current && !options.alongside) {
      this.app.notice('an export is running: Cancel it first', 'warn');
      return null;
    }
    const samples = this.app.samples();
    if (!samples) {
      this.app.notice('record a path (or add 2 tour views) first', 'warn');
      return null;
    }
    const [w, h] = (options.size || $('export-size').value).split('x').map(Number);
    const fps = options.fps || Number($('export-fps').value);
    const id = this.nextId++;
    const sent = this.app.exportVideo({
      exportId: id, path: pathFloats(samples), width: w, height: h, fps, pipeline: options.pipeline || '',
    });
    if (!sent) return null;
    if (options.alongside) {
      this.others.set(id, null);
      return id;
    }
    this.current = { id, assembler: null };
    this.last = null;
    this._show({ frames_done: 0, frames_total: 0, eta_ms: 0 }, 'sending the path…');
    return id;
  }

  cancel() {
    if (!this.current) return false;
    this.app.cancelExport(this.current.id);
    return true;
  }

  onProgress(p) {
    if (this.others.has(p.export_id)) this.others.set(p.export_id, p);
    if (!this.current || p.export_id !== this.current.id) return;
    this.last = p;
    this._show(p, progressText(p));
    if (p.error || p.cancelled) {
      this.current = null;
      $('btn-export-cancel').hidden = true;
      // The panel says it; a closed panel (the viewer moved on) gets a notice instead.
      if (p.error && $('paths').hidden) this.app.notice(progressText(p), 'error', 6000);
    } else if (p.done) {
      this.current.assembler = new ChunkAssembler(p.bytes);
    }
  }

  onChunk(c) {
    const cur = this.current;
    if (!cur || c.export_id !== cur.id || !cur.assembler) return;
    let complete = false;
    try {
      complete = cur.assembler.add(c);
    } catch (e) {
      this.current = null;
      this.app.notice(`export download failed: ${e.message}`, 'error', 6000);
      return;
    }
    $('export-progress').value = cur.assembler.received / cur.assembler.size;
    if (!complete) return;
    const blob = new Blob(cur.assembler.parts, { type: 'video/mp4' });
    if (this.file) URL.revokeObjectURL(this.file.url);
    this.file = { url: URL.createObjectURL(blob), bytes: blob.size, name: `catgs-export-${cur.id}.mp4` };
    const a = $('export-download');
    a.href = this.file.url;
    a.download = this.file.name;
    a.textContent = `Download ${this.file.name} (${sizeText(blob.size)})`;
    a.hidden = false;
    $('export-status').textContent = `ready: ${this.last.frames_total} frames, ${this.last.duration_s.toFixed(1)} s`;
    $('btn-export-cancel').hidden = true;
    this.current = null;
  }

  // The session ended: its export ended with it on the server.
  onClosed() {
    if (!this.current) return;
    this.current = null;
    $('export-status').textContent = 'export stopped: the connection closed';
    $('btn-export-cancel').hidden = true;
  }

  _show(p, text) {
    $('export-row').hidden = false;
    $('export-download').hidden = true;
    $('btn-export-cancel').hidden = !this.current;
    $('export-progress').value = p.frames_total ? p.frames_done / p.frames_total : 0;
    $('export-status').textContent = text;
  }

  snapshot() {
    return {
      running: this.current ? this.current.id : null,
      progress: this.last ? { ...this.last } : null,
      others: Object.fromEntries([...this.others].map(([id, p]) => [id, p && { ...p }])),
      file: this.file ? { ...this.file } : null,
      status: $('export-status').textContent,
    };
  }
}
