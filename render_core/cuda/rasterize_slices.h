// Stage 5 with task splitting (rasterize_slices.cu; mirrors cpu/rasterize_slices.cpp).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include "task_split.h"

namespace catgs::cuda::stages {

// Stage 5 with slices (rasterize_slices.cu; mirrors cpu::rasterize_slices): one block per slice
// (block b takes slice order[b] (plan_slices), where kNoSlice returns at once, or slice b
// without an order, where `blocks` must not exceed the slice total). A tile's only slice writes C + T * background to the image; a slice of a
// split tile writes its partial colour and transmittance to partials [slots, 256] (C.rgb, T).
// `early_termination`: stop a pixel before T would drop below 1e-4 within its slice; a pixel's
// composition ends at the first slice in which it stops or after which its transmittance is
// below 1e-4, so a later slice skips the pixels whose earlier slices, finished before it starts,
// already end it, and a slice behind one that saturated its tile alone is skipped entirely (see
// rasterize_slices.cu: the paper's higher early-termination threshold for later slices). A
// stopped pixel's partial T is stored negated. The last slice of a split tile to finish merges
// it: C = sum_k C_k prod_{m<k} T_m, then + prod T * background (paper sec. 3.4), the sum ending
// after the first slice in which the pixel stopped or after which prod T < 1e-4 (as
// cpu::rasterize_slices). The plan's per-tile state (saturated_from all ones, slices_done and
// slot_finished zero) must hold at launch, and holds again when the kernel ends.
// `tile_culling`: each round blends only the entries whose ellipse reaches the tile at this
// frame's features (blend_range_culled; same image, for lists built for other poses too).
// `abandon` (device, or null): when it holds non-zero at launch, draw nothing (a sub-frame
// that failed its check and will be drawn again as a key frame).
// `opaque` (tile null: none): the occlusion map's opaque points (forward_model/occlusion.h; as
// cpu::rasterize_slices): tile [tiles] each drawn tile's P, all ones where a pixel never got
// there (tiles without slices are left as they are: the caller fills it with all ones first);
// partial [slots, 256] scratch beside `partials`: a split tile's slices' pixels' own crossings,
// which the merge reads; pixel [H, W]: each drawn pixel's view depth of the entry before its own
// opaque point, the largest finite float where it has none (the per-pixel map; the caller fills
// the pixels of tiles without slices).
struct OpaquePoints {
  uint32_t* tile = nullptr;
  uint32_t* partial = nullptr;
  float* pixel = nullptr;
};
void rasterize_slices(const SlicePlan& plan, const uint32_t* order, uint32_t blocks, const uint32_t* sorted_values,
                      const Projected& projected, const CameraParams& cam, bool early_termination, bool tile_culling,
                      float3 background, const unsigned* abandon, float4* partials, float* out_rgb, uint32_t* out_rgba8,
                      cudaStream_t stream, OpaquePoints opaque = {});
}  // namespace catgs::cuda::stages
