// Images for the tools and tests: PNG files (stb, Debian's libstb), PSNR and SSIM. Not part of the
// render core, which hands images over in memory (renderer/renderer.h Image).
#pragma once

#include <string>

#include "renderer/renderer.h"

namespace catgs {

// PSNR in dB of two 8-bit images over RGB (alpha ignored); +inf when identical.
// Throws std::invalid_argument when sizes differ.
double psnr_rgba8(const Image& a, const Image& b);

// SSIM (Wang, Bovik, Sheikh, Simoncelli 2004, eq. 13: K1 0.01, K2 0.03, L 255) of two 8-bit
// images' luma (BT.709 Y' from R'G'B', full range, alpha ignored), the mean over 8x8 windows
// placed every 4 pixels (the uniform-window variant x264 and FFmpeg report; sample variances
// with 1/N). 1 for identical images, lower for worse. Throws std::invalid_argument when sizes
// differ or an image is smaller than 8x8.
double ssim_luma_rgba8(const Image& a, const Image& b);

// An anti-aliased image from one rendered `factor` times larger in each direction: each output
// pixel is the mean of its factor x factor block of `hi`'s float colours, each clamped to [0, 1]
// first (what a display shows of a sample), then rounded to 8 bits as the renderer does
// (to_unorm8). The reference of supersampling evaluations (render large, box-filter down, as
// Mip-Splatting's multi-scale tests do). Throws std::invalid_argument when factor < 1, `hi` has
// no float colours, or its size is not a multiple of factor.
Image box_downsample(const Image& hi, int factor);

// Writes out.rgba8 as an 8-bit RGB PNG. Throws std::runtime_error naming the path.
void write_png(const Image& image, const std::string& path);
// Reads an 8-bit PNG (RGB or RGBA) into rgba8 (rgb left empty). Throws std::runtime_error.
Image read_png(const std::string& path);

}  // namespace catgs
