// YUV 4:2:0 planes (I420: Y, then U = Cb, then V = Cr, 8-bit) in BT.709 limited range, the
// format every encoder of the server consumes, and the CPU reference colour conversion from
// RGBA8 (docs/DESIGN.md "Data flow of a frame": the frame is converted where it was rendered).
//
// The CUDA core converts a frame on the GPU with the same maths in double precision
// (render_core/cuda/yuv420_convert.cu, checked code value for code value against the function
// below by tests/gpu); Renderer::render_yuv420_at() is the one entry point for both.
#pragma once

#include <cstdint>
#include <vector>

namespace catgs {

// Borrowed, read-only 8-bit I420 planes of a width x height picture (width and height even).
// Y is width x height samples, U and V are (width / 2) x (height / 2); each row starts
// `*_stride` bytes after the previous one (stride >= the row's sample count). Values are BT.709
// limited range: Y in [16, 235], Cb/Cr in [16, 240]. Chroma is sited at the centre of each 2x2
// block.
struct Yuv420Planes {
  const std::uint8_t* y = nullptr;
  int y_stride = 0;
  const std::uint8_t* u = nullptr;
  int u_stride = 0;
  const std::uint8_t* v = nullptr;
  int v_stride = 0;
};

// Where a picture is written: host memory, or CUDA device memory of the current device (the
// CUDA runtime's primary context; an NVENC hw frame, say).
enum class MemoryKind { host, device };

// Writable I420 planes of a width x height picture, layout as Yuv420Planes.
struct Yuv420Target {
  int width = 0, height = 0;
  MemoryKind memory = MemoryKind::host;
  std::uint8_t* y = nullptr;
  int y_stride = 0;
  std::uint8_t* u = nullptr;
  int u_stride = 0;
  std::uint8_t* v = nullptr;
  int v_stride = 0;
};

// Owned, tightly packed host I420 (strides = width, width / 2, width / 2).
struct Yuv420Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> y, u, v;
  Yuv420Planes planes() const { return {y.data(), width, u.data(), width / 2, v.data(), width / 2}; }
  // Sizes the planes for width x height and returns them as a host target.
  Yuv420Target target(int w, int h);
};

// RGBA8 (full-range BT.709/sRGB primaries, alpha ignored; `stride_bytes` per row, top row
// first) -> BT.709 limited-range I420 written into `out` (a host target of the same size):
// Y' = 16 + 219 (0.2126 R + 0.7152 G + 0.0722 B) per pixel, Cb/Cr = 128 + 224 (B - Y) / 1.8556
// and (R - Y) / 1.5748 on the 2x2 mean of R, G, B (ITU-R BT.709-6 table 3; R, G, B in [0, 1]),
// in double precision, rounded to nearest (halves away from zero). Throws std::invalid_argument
// for an odd or non-positive size, a device target or a target of another size.
void rgba_to_yuv420_bt709(const std::uint8_t* rgba, int width, int height, int stride_bytes, const Yuv420Target& out);

// The same into a new tightly packed image.
Yuv420Image rgba_to_yuv420_bt709(const std::uint8_t* rgba, int width, int height, int stride_bytes);

// Checks a target for a width x height picture: even positive size, matching target size,
// non-null planes, strides >= width (Y) and width / 2 (U, V). Throws std::invalid_argument
// naming `who` and the problem.
void check_yuv420_target(const char* who, const Yuv420Target& t, int width, int height);

}  // namespace catgs
