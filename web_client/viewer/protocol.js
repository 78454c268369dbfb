// The wire protocol (proto/catgs_stream.proto, package catgs.stream.v1) through protobufjs
// reflection: the schema is loaded at run time, so the page and the server cannot drift apart by
// a code-generation step. Field names are kept as in the .proto (keepCase), e.g. client_time_ms.

export const PROTOCOL_VERSION = 1;
const PKG = 'catgs.stream.v1';

// Loads the schema with the protobufjs runtime (`pb`: the global `protobuf` from
// vendor/protobuf.min.js in the page, the npm module in node). The .proto is served beside the
// page; a static server that will not serve the .proto extension (libwebsockets answers 415 for
// unknown types) is covered by the JSON descriptor that scripts/setup_web.sh generates from it.
//
// The result's `sessionOriginRefused` is true where the server answered the schema with
// `catgs-session-origin: refused`: this page's origin may not open a session there (the server's
// --allowed-origins; server/transport/transport.h).
export async function loadProtocol(pb, baseUrl = '') {
  const errors = [];
  const refused = (res) => res.headers.get('catgs-session-origin') === 'refused';
  try {
    const res = await fetch(`${baseUrl}catgs_stream.proto`, { cache: 'no-cache' });
    if (!res.ok) throw new Error(`HTTP ${res.status}`);
    const text = await res.text();
    return { ...makeProtocol(pb.parse(text, { keepCase: true }).root), sessionOriginRefused: refused(res) };
  } catch (e) {
    errors.push(`catgs_stream.proto: ${e.message || e}`);
  }
  try {
    const res = await fetch(`${baseUrl}catgs_stream.json`, { cache: 'no-cache' });
    if (!res.ok) throw new Error(`HTTP ${res.status}`);
    return { ...makeProtocol(pb.Root.fromJSON(await res.json())), sessionOriginRefused: refused(res) };
  } catch (e) {
    errors.push(`catgs_stream.json: ${e.message || e}`);
  }
  throw new Error(`cannot load the protocol schema (${errors.join('; ')})`);
}

const vec3 = (v) => ({ x: v[0], y: v[1], z: v[2] });
const quat = (q) => ({ w: q[0], x: q[1], y: q[2], z: q[3] });
const eyeView = (e) => ({
  position: vec3(e.position),
  orientation: quat(e.orientation),
  angle_left: e.angles.left,
  angle_right: e.angles.right,
  angle_up: e.angles.up,
  angle_down: e.angles.down,
});

// A message's EyeView (Frame.left_eye / right_eye, decoded) in the page's form: { position,
// orientation, angles: { left, right, up, down } }; null where it is absent.
export function eyeViewFromWire(e) {
  if (!e || !e.position || !e.orientation) return null;
  const n = (v) => Number(v) || 0;
  return {
    position: [n(e.position.x), n(e.position.y), n(e.position.z)],
    orientation: [n(e.orientation.w), n(e.orientation.x), n(e.orientation.y), n(e.orientation.z)],
    angles: { left: n(e.angle_left), right: n(e.angle_right), up: n(e.angle_up), down: n(e.angle_down) },
  };
}

export function makeProtocol(root) {
  // protobufjs 7.6 works out a field's wire features (packed repeated floats: ExportVideoRequest
  // .path) when the schema is resolved; unresolved, it writes them unpacked, 25% larger.
  root.resolveAll();
  const ClientMessage = root.lookupType(`${PKG}.ClientMessage`);
  const ServerMessage = root.lookupType(`${PKG}.ServerMessage`);
  const Codec = root.lookupEnum(`${PKG}.Codec`);
  const ErrorCode = root.lookupEnum(`${PKG}.ErrorCode`);

  const encode = (body) => {
    const obj = ClientMessage.fromObject(body);
    return ClientMessage.encode(obj).finish();
  };

  return {
    root,
    Codec: Codec.values,
    ErrorCode: ErrorCode.values,
    codecName: (v) => Codec.valuesById[v] || `codec ${v}`,
    errorCodeName: (v) => ErrorCode.valuesById[v] || `ERROR_${v}`,

    // `scene`: a scene name from GET /scenes ('' the server's first; servers before it ignore it).
    // `loadProgress`: ask for LoadProgress messages while the scene loads (before Welcome).
    // `codecs`: Codec values the page decodes, in order of preference (decoder.js decodableCodecs).
    encodeHello({
      width, height, token = '', clientName = 'catgs-web', scene = '', loadProgress = false,
      codecs = [Codec.values.CODEC_H264],
    }) {
      return encode({
        hello: {
          protocol_version: PROTOCOL_VERSION,
          viewport_width: width,
          viewport_height: height,
          codecs,
          token,
          client_name: clientName,
          scene,
          load_progress: loadProgress,
        },
      });
    },

    // receipt: the newest frame's { sequence, receivedMs } (receivedMs 0: none). A headset
    // (issue 94) adds both eyes, leftEye and rightEye, each { position, orientation, angles:
    // { left, right, up, down } (radians, XrFovf's) } in the pose's conventions (stereo.js
    // eyeViewOf); position, orientation and fovDeg stay the head's. displayHz: the rate the
    // display shows frames at (a headset's; 0 unknown: the server takes 60), 0 or in [24, 240].
    encodePose({ sequence, clientTimeMs, position, orientation, fovDeg, shownLatencyMs = 0,
      receipt = { sequence: 0, receivedMs: 0 }, leftEye = null, rightEye = null, displayHz = 0 }) {
      const pose = {
        sequence,
        client_time_ms: clientTimeMs,
        position: vec3(position),
        orientation: quat(orientation),
        vertical_fov_deg: fovDeg,
        shown_latency_ms: shownLatencyMs,
        received_frame_sequence: receipt.sequence,
        received_ms: receipt.receivedMs,
      };
      if (leftEye && rightEye) {
        pose.left_eye = eyeView(leftEye);
        pose.right_eye = eyeView(rightEye);
      }
      if (displayHz > 0) pose.display_hz = displayHz;
      return encode({ pose });
    },

    encodeResize(width, height) {
      return encode({ resize: { viewport_width: width, viewport_height: height } });
    },

    encodePing(clientTimeMs) {
      return encode({ ping: { client_time_ms: clientTimeMs } });
    },

    encodeKeyFrameRequest() {
      return encode({ key_frame_request: {} });
    },

    encodeQuality(maxBitrateKbps) {
      return encode({ quality: { max_bitrate_kbps: maxBitrateKbps } });
    },

    // What lies under pixel (x, y) of a width x height view of `pose` (DepthResult answers).
    encodeDepthRequest({ requestId, x, y, width, height, pose }) {
      return encode({
        depth_request: {
          request_id: requestId,
          x,
          y,
          width,
          height,
          pose: {
            position: vec3(pose.position),
            orientation: quat(pose.orientation),
            vertical_fov_deg: pose.fovDeg,
          },
        },
      });
    },

    // An author saves the scene's annotations (the JSON of server/session/annotations.h).
    encodeSaveAnnotations(json) {
      return encode({ save_annotations: { json } });
    },

    // Render `path` (9 floats a pose: video_export.js pathFloats) to an MP4 on the server.
    encodeExportVideo({ exportId, path, width, height, fps, pipeline = '' }) {
      return encode({ export_video: { export_id: exportId, path, width, height, fps, pipeline } });
    },

    encodeExportCancel(exportId) {
      return encode({ export_cancel: { export_id: exportId } });
    },

    // -> { kind: 'welcome' | 'frame' | 'stats' | 'error' | 'pong' | 'load_progress' | 'depth_result' |
    //      'annotations' | 'export_progress' | 'export_chunk' | null, msg }
    decodeServer(bytes) {
      const m = ServerMessage.decode(bytes);
      const kind = m.body || null; // protobufjs' oneof getter names the field that is set
      return { kind, msg: kind ? m[kind] : null };
    },

    // For tests: the inverse directions.
    decodeClient(bytes) {
      const m = ClientMessage.decode(bytes);
      const kind = m.body || null;
      return { kind, msg: kind ? m[kind] : null };
    },
    encodeServer(body) {
      return ServerMessage.encode(ServerMessage.fromObject(body)).finish();
    },
  };
}
