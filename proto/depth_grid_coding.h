// Frame.depth_grid's coding (catgs_stream.proto DepthGrid; issue 91): a renderer's depth grid
// (render_core/forward_model/depth_grid.h) as one byte of inverse depth a vertex, and back. The
// server packs each exact frame's grid; catgs-loadgen and catgs-shown read it; the page reads it
// in web_client/viewer/depth_warp.js by the same rule.
//
// Inverse depth w = 1 / z (world units^-1), linear in 255 codes up to the grid's largest
// (inverse_depth_max: its nearest vertex): code c = max(1, round(255 w / w_max)) for a surface,
// 0 for none (z = +inf, the background). Inverse depth, because a step b sideways moves a point's
// image by f b w pixels (f the focal length): a linear code spends its precision evenly on
// parallax, and the background's w = 0 is a code of its own. A vertex nearer than 1/255 of the
// range's top therefore reads as that (a far vertex of a grid whose nearest lies close). The codes
// travel deflated (zlib, RFC 1950; their share of a stream's bytes, deflated and raw: RESULTS.md,
// "What the visitor's screen shows").
#pragma once

#include <string>
#include <vector>

#include "catgs_stream.pb.h"
#include "renderer/renderer.h"

namespace catgs::server {

namespace pb = ::catgs::stream::v1;

// Packs `grid` (cols > 0) into `out`. Depths that are not finite and positive are no surface.
// Throws std::runtime_error where zlib fails (out of memory).
void pack_depth_grid(const DepthGrid& grid, pb::DepthGrid* out);

// The grid a Frame carries: depths (+inf where code 0), cols x rows. Throws std::invalid_argument
// naming what is wrong where the message is malformed: a zero or oversized shape (over 4097 a
// side), bytes that do not inflate to exactly cols x rows codes, a cell of 0, or an
// inverse_depth_max not finite and positive while some code is not 0.
DepthGrid unpack_depth_grid(const pb::DepthGrid& in);

}  // namespace catgs::server
