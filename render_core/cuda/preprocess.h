// Stage 1 of the CUDA core (preprocess.cu; mirrors cpu/preprocess.cpp).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// Stage 1 (preprocess.cu): chunk culling (exact: fm::chunk_outside_view, a block per chunk),
// frustum culling, EWA 2D covariance, conic, SH colour, tile bounds and
// per-Gaussian tile counts (vanilla: 3-sigma square; exact: opacity-aware ellipse-vs-tile test).
// Adds the number of visible Gaussians to *visible (one atomic per block), and widens
// depth_range[2] to the listed Gaussians' view depths (float bits; [0] complemented, both
// running maxima: zero them first) for the packed sort keys (DepthKeyPacking). Big Gaussians are
// appended to `big` (one atomic per warp that holds any); with `exact`, their tiles are counted
// by a second kernel, a warp per Gaussian. `big.count` must be zero on entry. Writes each chunk's
// entry count to out.chunk_total.
void preprocess(const SceneView& scene, const CameraParams& cam, bool exact, const Projected& out,
                unsigned long long* visible, unsigned long long* depth_range, const BigList& big, cudaStream_t stream);

// Stage 1, big Gaussians (preprocess.cu): a warp per Gaussian of `big` counts the tiles of its
// rectangle passing `tests` into tiles_touched, adds them to its chunk's chunk_total, and adds the
// Gaussians found visible to *visible.
void count_big_tiles(const BigList& big, const TileTests& tests, const ushort4* rect, uint32_t* tiles_touched,
                     uint32_t* chunk_total, unsigned long long* visible, cudaStream_t stream);

}  // namespace catgs::cuda::stages
