// Images for the tools and tests: PNG files (stb, Debian's libstb) and PSNR. Not part of the
// render core, which hands images over in memory (renderer/renderer.h Image).
#pragma once

#include <string>

#include "renderer/renderer.h"

namespace catgs {

// PSNR in dB of two 8-bit images over RGB (alpha ignored); +inf when identical.
// Throws std::invalid_argument when sizes differ.
double psnr_rgba8(const Image& a, const Image& b);

// Writes out.rgba8 as an 8-bit RGB PNG. Throws std::runtime_error naming the path.
void write_png(const Image& image, const std::string& path);
// Reads an 8-bit PNG (RGB or RGBA) into rgba8 (rgb left empty). Throws std::runtime_error.
Image read_png(const std::string& path);

}  // namespace catgs
