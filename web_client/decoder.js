// WebCodecs decoding of the H.264 stream: Annex B chunks with no `description` (Chromium accepts
// that: SPS and PPS travel in band on every IDR), configured from the SPS of the first IDR and
// reconfigured when a key frame brings another codec string or frame size (e.g. after a Resize).

import { inspectAccessUnit } from './h264.js';

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
    let info;
    try {
      info = inspectAccessUnit(payload);
    } catch (e) {
      this._fail(e);
      return;
    }
    const isKey = !!f.key_frame || info.hasIdr;
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
            // No description: the stream is Annex B with SPS/PPS in band on every IDR.
            this.decoder.configure({ codec: want.codec, optimizeForLatency: true });
            this.config = want;
          }
        } else if (!this.config) {
          this._askForKey(false); // an IDR without SPS cannot start a stream
          return;
        }
      }
      const timestamp = this.nextTimestamp++;
      this.meta.set(timestamp, {
        sequence: f.sequence,
        poseSequence: f.pose_sequence,
        clientTimeMs: f.client_time_ms,
        width: f.width,
        height: f.height,
        keyFrame: isKey,
      });
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
