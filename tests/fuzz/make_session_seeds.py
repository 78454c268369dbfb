#!/usr/bin/env python3
"""Writes the seed corpus of fuzz_session (corpus/session/*.bin): client connections in the
target's record layout (fuzz_session.cpp), their messages encoded by protoc from protobuf text,
so the seeds follow proto/catgs_stream.proto rather than our own encoder.

usage: tests/fuzz/make_session_seeds.py   (from anywhere; needs protoc on PATH)
"""
import pathlib
import struct
import subprocess

HERE = pathlib.Path(__file__).resolve().parent
PROTO_DIR = HERE.parent.parent / "proto"
OUT = HERE / "corpus" / "session"

BINARY, TEXT, OVERSIZE, WRITTEN, PAUSE, FAULT = 0, 1, 2, 3, 4, 5


def encode(text):
    """A ClientMessage from protobuf text, encoded by protoc."""
    return subprocess.run(
        ["protoc", f"--proto_path={PROTO_DIR}", "--encode=catgs.stream.v1.ClientMessage", "catgs_stream.proto"],
        input=text.encode(), capture_output=True, check=True).stdout


def hello(w=32, h=24, extra=""):
    return encode(f"hello {{ protocol_version: 1 viewport_width: {w} viewport_height: {h} codecs: CODEC_H264 "
                  f"client_name: \"seed\" load_progress: true {extra} }}")


def pose(seq, z=-1.5):
    """A camera 1.1 units in front of the chunk (its centre is near (-0.12, -2.26, -0.36)), looking
    along +z (OpenCV axes), moving sideways with the sequence number."""
    return encode(f"pose {{ sequence: {seq} client_time_ms: {1000 + 16.7 * seq} "
                  f"position {{ x: {-0.12 + 0.01 * seq:.3f} y: -2.26 z: {z} }} "
                  f"orientation {{ w: 1 }} vertical_fov_deg: 55 shown_latency_ms: 40 }}")


def message(data, op=BINARY):
    return bytes([op]) + struct.pack("<H", len(data)) + data


def connection(*records):
    out = b""
    for r in records:
        out += bytes([r]) if isinstance(r, int) else r
    return out


SEEDS = {
    # Hello, three poses, each frame written before the next pose.
    "stream": connection(message(hello()), PAUSE, message(pose(1)), PAUSE, WRITTEN, message(pose(2, -1.4)), PAUSE,
                         WRITTEN, message(pose(3, -1.3)), PAUSE, WRITTEN),
    # A new size, a key-frame request and a bitrate cap mid-stream, each followed by a pose.
    "changes": connection(message(hello()), message(pose(1)), PAUSE, WRITTEN,
                          message(encode("resize { viewport_width: 48 viewport_height: 32 }")), message(pose(2)),
                          PAUSE, WRITTEN, message(encode("key_frame_request {}")), message(pose(3)), PAUSE, WRITTEN,
                          message(encode("quality { max_bitrate_kbps: 300 }")), message(pose(4)), PAUSE, WRITTEN),
    # Poses faster than frames are written: latest pose wins, at most two frames in flight.
    "flood": connection(message(hello()), *[message(pose(i, -1.5 + 0.02 * i)) for i in range(1, 9)], PAUSE,
                        message(pose(9)), PAUSE, message(pose(10)), PAUSE, WRITTEN, PAUSE),
    # Allocations that fail (issue 73): at the first frame, after a resize and at a larger one.
    "fault": connection(message(hello()), PAUSE, FAULT, message(pose(1)), PAUSE, WRITTEN, FAULT,
                        message(encode("resize { viewport_width: 64 viewport_height: 48 }")), message(pose(2)), PAUSE,
                        WRITTEN, FAULT, message(pose(3)), PAUSE, WRITTEN, message(pose(4)), PAUSE, WRITTEN),
    "ping": connection(message(hello()), PAUSE, message(encode("ping { client_time_ms: 99 }")), PAUSE),
    # The disconnect while a render is queued.
    "gone_mid_render": connection(message(hello()), PAUSE, message(pose(1))),
    # Refusals: no Hello first, a second Hello, a text frame, an oversize message, a viewport
    # above --max-viewport, a bad pose, a scene that is not served.
    "pose_first": connection(message(pose(1)), PAUSE),
    "second_hello": connection(message(hello()), PAUSE, message(hello()), PAUSE),
    "text": connection(message(hello()), PAUSE, message(b"hello", TEXT), PAUSE),
    "oversize": connection(message(hello()), PAUSE, bytes([OVERSIZE]), PAUSE),
    "too_large": connection(message(hello(640, 480)), PAUSE),
    "bad_pose": connection(message(hello()), PAUSE,
                           message(encode("pose { sequence: 1 orientation { w: 1e200 } vertical_fov_deg: 55 }")), PAUSE),
    "unknown_scene": connection(message(hello(extra='scene: "nowhere"')), PAUSE),
    # Export video: a two-pose path (refused here: the target's server has no author token), a
    # cancel of an export that is not running, then the stream goes on.
    "export": connection(message(hello()), PAUSE, message(encode(
        "export_video { export_id: 1 width: 32 height: 24 fps: 10 "
        + "".join(f"path: {v} " for v in [0, -0.12, -2.26, -1.5, 1, 0, 0, 0, 55, 0.5, -0.1, -2.26, -1.5, 1, 0, 0, 0, 55])
        + "}")), PAUSE, message(encode("export_cancel { export_id: 1 }")), message(pose(1)), PAUSE, WRITTEN),
}


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    for name, data in SEEDS.items():
        (OUT / f"{name}.bin").write_bytes(data)
    print(f"wrote {len(SEEDS)} seeds to {OUT}")


if __name__ == "__main__":
    main()
