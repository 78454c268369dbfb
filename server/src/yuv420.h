// YUV 4:2:0 planes (I420: Y, then U = Cb, then V = Cr, 8-bit) in BT.709 limited range, the
// format every encoder here consumes, and the CPU reference conversion from RGBA8.
//
// A GPU frame is converted by a CUDA kernel with the same maths (only the planes cross to the
// host); the CPU reference below is what that kernel and swscale are checked against.
#pragma once

#include <cstdint>
#include <vector>

namespace catgs::server {

// Borrowed 8-bit I420 planes of a width x height picture (width and height even). Y is
// width x height samples, U and V are (width / 2) x (height / 2); each row starts `*_stride`
// bytes after the previous one (stride >= the row's sample count). Values are BT.709 limited
// range: Y in [16, 235], Cb/Cr in [16, 240]. Chroma is sited at the centre of each 2x2 block.
struct Yuv420Planes {
  const std::uint8_t* y = nullptr;
  int y_stride = 0;
  const std::uint8_t* u = nullptr;
  int u_stride = 0;
  const std::uint8_t* v = nullptr;
  int v_stride = 0;
};

// Owned, tightly packed I420 (strides = width, width / 2, width / 2).
struct Yuv420Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> y, u, v;
  Yuv420Planes planes() const {
    return {y.data(), width, u.data(), width / 2, v.data(), width / 2};
  }
};

// RGBA8 (full-range BT.709/sRGB primaries, alpha ignored; `stride_bytes` per row, top row
// first) -> BT.709 limited-range I420: Y' = 16 + 219 (0.2126 R + 0.7152 G + 0.0722 B), Cb/Cr =
// 128 + 224 (B - Y) / 1.8556 and (R - Y) / 1.5748 on the 2x2 mean of R, G, B (ITU-R BT.709-6
// table 3; R, G, B in [0, 1]). Rounded to nearest. Throws std::invalid_argument for an odd or
// non-positive size.
Yuv420Image rgba_to_yuv420_bt709(const std::uint8_t* rgba, int width, int height,
                                 int stride_bytes);

}  // namespace catgs::server
