#include "encode/h264_level.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace catgs::server {

namespace {

struct Level {
  int idc;          // level_idc (10 x the level number)
  double max_mbps;  // MaxMBPS: macroblocks a second
  double max_fs;    // MaxFS: macroblocks a frame
};

// Table A-1 (level 1b left out: it has level 1's limits).
constexpr Level kLevels[] = {
    {10, 1485, 99},       {11, 3000, 396},       {12, 6000, 396},       {13, 11880, 396},       {20, 11880, 396},
    {21, 19800, 792},     {22, 20250, 1620},     {30, 40500, 1620},     {31, 108000, 3600},     {32, 216000, 5120},
    {40, 245760, 8192},   {41, 245760, 8192},    {42, 522240, 8704},    {50, 589824, 22080},    {51, 983040, 36864},
    {52, 2073600, 36864}, {60, 4177920, 139264}, {61, 8355840, 139264}, {62, 16711680, 139264},
};

bool fits(const Level& l, double mb_w, double mb_h, double fps) {
  const double side = std::sqrt(8.0 * l.max_fs);  // A.3.1 h) and i): each side <= sqrt(8 MaxFS)
  return mb_w * mb_h <= l.max_fs && mb_w <= side && mb_h <= side && mb_w * mb_h * fps <= l.max_mbps;
}

}  // namespace

int h264_level(int width, int height, double fps) {
  if (width <= 0 || height <= 0 || !(fps > 0))
    throw std::invalid_argument("H.264 level: size and fps must be positive");
  const double mb_w = std::ceil(width / 16.0), mb_h = std::ceil(height / 16.0);
  for (const Level& l : kLevels)
    if (fits(l, mb_w, mb_h, fps)) return l.idc;
  const Level& top = kLevels[sizeof kLevels / sizeof kLevels[0] - 1];
  const std::string size = std::to_string(width) + "x" + std::to_string(height);
  if (mb_w * mb_h > top.max_fs)
    throw std::invalid_argument(size +
                                " is too big for H.264 (level 6.2): " + std::to_string(static_cast<long>(mb_w * mb_h)) +
                                " macroblocks a frame, " + std::to_string(static_cast<long>(top.max_fs)) + " at most");
  if (!fits(top, mb_w, mb_h, 1.0))
    throw std::invalid_argument(size + " is too long a side for H.264 (level 6.2): at most " +
                                std::to_string(static_cast<long>(std::sqrt(8.0 * top.max_fs)) * 16) + " pixels");
  throw std::invalid_argument(size + " at " + std::to_string(fps) + " fps is too fast for H.264 (level 6.2): " +
                              std::to_string(static_cast<long>(mb_w * mb_h * fps)) + " macroblocks a second, " +
                              std::to_string(static_cast<long>(top.max_mbps)) + " at most");
}

}  // namespace catgs::server
