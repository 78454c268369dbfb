// H.264 level limits (ITU-T H.264, Annex A, Table A-1): the largest frame and macroblock rate a
// decoder of each level must take. A video beyond level 6.2, the highest, is not H.264 that
// players promise to decode, so catgs-render refuses it before rendering.
#pragma once

namespace catgs::server {

// The lowest level (level_idc: 52 for level 5.2) whose limits a width x height stream at `fps`
// frames a second fits: frame size in 16x16 macroblocks <= MaxFS, each side in macroblocks <=
// sqrt(8 MaxFS), macroblocks a second <= MaxMBPS. 3840x2160 at 60: 5.2; 1920x1080 at 60: 4.2.
// Throws std::invalid_argument saying which limit of level 6.2 the size or rate exceeds (e.g.
// 8192x8192: 262,144 macroblocks a frame, 139,264 at most), or for a size or fps <= 0.
int h264_level(int width, int height, double fps);

}  // namespace catgs::server
