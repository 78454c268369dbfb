// WebCodecs decoding of the stream: H.264 as Annex B chunks with no `description` (Chromium
// accepts that: SPS and PPS travel in band on every IDR), configured from the SPS of the first
// IDR; AV1 as temporal units of low-overhead OBUs, configured from the sequence header OBU of its
// key frames. Reconfigured when a key frame brings another codec (Frame.codec: the server moved the
// session between H.264 and AV1), codec string or frame size (e.g. after a Resize).

import { inflateDepthGrid } from './depth_warp.js';
import { inspectAccessUnit } from './h264.js';
import { inspectTemporalUnit } from './av1.js';
import { eyeViewFromWire } from './protocol.js';

// Frame.shown_pose (the server predicted where the visitor will be when the frame is shown,
// server/session/pose_prediction.h) as the page's pose { position, orientation, fovDeg }; null
// where the frame shows the Pose it answers.
function shownPoseOf(p) {
  if (!p || !p.position || !p.orientation) return null;
  const n = (v) => Number(v) || 0;
  return {
    position: [n(p.position.x), n(p.position.y), n(p.position.z)],
    orientation: [n(p.orientation.w), n(p.orientation.x), n(p.orientation.y), n(p.orientation.z)],
    fovDeg: n(p.vertical_fov_deg),
  };
}

// Frame.codec / Welcome.codec values (proto/catgs_stream.proto, enum Codec).
export const CODEC_H264 = 1;
export const CODEC_AV1 = 2;

// A codec string of each kind for VideoDecoder.isConfigSupported: H.264 constrained baseline
// level 4.0 (1080p), AV1 main profile level 4.0 (seq_level_idx 8), 8 bits.
const PROBE_CONFIGS = [
  [CODEC_AV1, 'av01.0.08M.08'],
  [CODEC_H264, 'avc1.42E028'],
];

// The codecs this browser's WebCodecs decodes, for Hello.codecs, AV1 first (the server streams
// it only where its host affords it). H.264 is always listed: the server may move any session to it.
export async function decodableCodecs() {
  const out = [];
  for (const [codec, string] of PROBE_CONFIGS) {
    try {
      const r = await VideoDecoder.isConfigSupported({ codec: string, optimizeForLatency: true });
      if (r.supported) out.push(codec);
    } catch (_) {
      // an unknown codec string: not decodable
    }
  }
  if (!out.includes(CODEC_H264)) out.push(CODEC_H264);
  return out;
}

// What a payload of `codec` says for the decoder: { codec string or null, key }.
function inspectPayload(codec, payload) {
  if (codec === CODEC_AV1) {
    const info = inspectTemporalUnit(payload);
    return { codec: info.codec, key: info.sequenceHeader !== null };
  }
  const info = inspectAccessUnit(payload);
  return { codec: info.codec, key: info.hasIdr };
}

export const hasWebCodecs = () =>
  typeof globalThis.VideoDecoder === 'function' && typeof globalThis.EncodedVideoChunk === 'function';

export class StreamDecoder {
  // onFrame(videoFrame, meta): the caller draws and must close the frame.
  // onError(error): a decode error (the decoder has already been reset).
  // requestKeyFrame(): ask the server for an IDR.
  constructor({ onFrame, onError, requestKeyFrame }) {
    this.onFrame = onFrame;
    this.onError = onError;
    this.requestKeyFrame = requestKeyFrame;
    this.decoder = null;
    this.config = null; // { codec, width, height } the decoder was configured with
    this.waitingForKey = true;
    this.nextTimestamp = 0;
    this.meta = new Map(); // chunk timestamp -> Frame metadata, to pair outputs with their Frame
    this.lastKeyRequestMs = -Infinity;
    this.errors = 0;
    this.streamCodec = CODEC_H264; // Welcome.codec: what a Frame without a codec carries
  }

  // A new session's Welcome.codec (0 from older servers: H.264).
  setWelcomeCodec(codec) {
    this.streamCodec = codec || CODEC_H264;
  }

  _create() {
    this.decoder = new VideoDecoder({
      output: (frame) => this._output(frame),
      error: (e) => this._fail(e),
    });
    this.config = null;
  }

  _output(frame) {
    const meta = this.meta.get(frame.timestamp);
    this.meta.delete(frame.timestamp);
    // Drop entries older than this output: the decoder never emits them now.
    for (const ts of this.meta.keys()) {
      if (ts < frame.timestamp) this.meta.delete(ts);
      else break;
    }
    this.onFrame(frame, meta);
  }

  _fail(e) {
    this.errors++;
    this.reset();
    this._askForKey(true);
    this.onError(e);
  }

  // Rate-limited so a decoder that keeps failing does not flood the server with requests.
  _askForKey(force) {
    const now = performance.now();
    if (!force && now - this.lastKeyRequestMs < 500) return;
    this.lastKeyRequestMs = now;
    this.requestKeyFrame();
  }

  // Forget the stream (new session, decoder error): the next decodable frame is a key frame.
  reset() {
    const d = this.decoder;
    this.decoder = null;
    this.config = null;
    this.waitingForKey = true;
    this.meta.clear();
    if (d && d.state !== 'closed') {
      try {
        d.close();
      } catch (_) {
        // already closed by the error path
      }
    }
  }

  // Decodes one protocol Frame message.
  decode(f) {
    const payload = f.payload;
    if (!payload || payload.length === 0) return;
    const codec = f.codec || this.streamCodec;
    let info;
    try {
      info = inspectPayload(codec, payload);
    } catch (e) {
      this._fail(e);
      return;
    }
    const isKey = !!f.key_frame || info.key;
    if (this.waitingForKey && !isKey) {
      this._askForKey(false);
      return; // a delta frame without its reference cannot be decoded
    }
    try {
      if (isKey) {
        if (!this.decoder || this.decoder.state === 'closed') this._create();
        if (info.codec) {
          const want = { codec: info.codec, width: f.width, height: f.height };
          const c = this.config;
          if (!c || c.codec !== want.codec || c.width !== want.width || c.height !== want.height) {
            // No description: H.264 is Annex B with SPS/PPS in band on every IDR, AV1 carries
            // its sequence header in band on every key frame.
            this.decoder.configure({ codec: want.codec, optimizeForLatency: true });
            this.config = want;
          }
        } else if (!this.config) {
          this._askForKey(false); // a key frame without SPS (sequence header) cannot start a stream
          return;
        }
      }
      const timestamp = this.nextTimestamp++;
      const meta = {
        sequence: f.sequence,
        poseSequence: f.pose_sequence,
        clientTimeMs: f.client_time_ms,
        shownPose: shownPoseOf(f.shown_pose),
        // Frame.depth_grid, inflated while the frame decodes (depth_warp.js): `depthGrid` the
        // promise, `depthGridReady` the grid once it is there (usually before the picture).
        depthGrid: null,
        depthGridReady: null,
        width: f.width,
        height: f.height,
        keyFrame: isKey,
        // A headset's frame (issue 94): both eyes side by side, the left in columns [0, eyeWidth),
        // the right in [eyeWidth, 2 eyeWidth), each as the server rendered it (the page
        // re-projects from these, not from what it sent). eyeWidth 0: a mono frame.
        eyeWidth: f.eye_width || 0,
        leftEye: eyeViewFromWire(f.left_eye),
        rightEye: eyeViewFromWire(f.right_eye),
      };
      if (f.depth_grid && f.depth_grid.cols) {
        meta.depthGrid = inflateDepthGrid(f.depth_grid).then((g) => (meta.depthGridReady = g));
        meta.depthGrid.catch(() => {}); // reported where it is used (catgs_viewer.js)
      }
      this.meta.set(timestamp, meta);
      this.decoder.decode(new EncodedVideoChunk({ type: isKey ? 'key' : 'delta', timestamp, data: payload }));
      this.waitingForKey = false;
    } catch (e) {
      this._fail(e);
    }
  }

  get codec() {
    return this.config ? this.config.codec : null;
  }

  get queueSize() {
    return this.decoder ? this.decoder.decodeQueueSize : 0;
  }
}
