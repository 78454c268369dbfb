// Stage 1 of the CUDA core (preprocess.cu; mirrors cpu/preprocess.cpp).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// Stage 1 (preprocess.cu): chunk culling first (exact: fm::chunk_outside_view, a thread per chunk;
// vanilla keeps every chunk), whose kept chunks `live` lists in index order (order_live_chunks;
// records.h LiveChunks: the k-th kept chunk's Gaussians take slot chunk k of `out`), then a block
// per kept chunk within live.capacity: frustum culling, EWA 2D covariance, conic, SH colour, tile
// bounds and per-Gaussian tile counts (vanilla: 3-sigma square; exact: opacity-aware
// ellipse-vs-tile test). Adds the number of visible Gaussians to *visible (one atomic per warp, at
// the end of its walk: no block barrier), and widens depth_range[2] to the view depths of the
// Gaussians with entries (float bits; [0] complemented, both running maxima: zero them first) for
// the single sort's key (fm::single_sort_packing). Big Gaussians' slots are appended to `big`, huge
// ones to its huge end (one atomic per warp that holds any); with `exact`, their tiles are counted
// by a second kernel (count_big_tiles). `big.count` must be zero on entry. Each slot chunk's entry
// count ends in out.chunk_total (zeroed first, then an atomic per warp with entries; 0 past the
// kept chunks). A frame whose kept chunks pass live.capacity pre-processes only the first
// live.capacity (the caller reads the count and draws it again with larger buffers). `region`: one
// pass of a frame drawn in passes (renderer/render_passes.h) counts only that region's tiles
// (fm::clip_tile_rect; the camera stays the whole frame's), as cpu::preprocess; fm::kAllTiles for a
// frame in one pass. `occlusion`: exact also drops the chunks that the last frame's map,
// reprojected onto this frame (its cells), hides whole (fm::chunk_hidden, in the chunk cull) and
// the entries of small Gaussians it hides (fm::entry_hidden, from the tile mask;
// forward_model/occlusion.h). A map without cells (the default) drops none.
void preprocess(const SceneView& scene, const CameraParams& cam, bool exact, const fm::TileRect& region,
                const Projected& out, const LiveChunks& live, unsigned long long* visible,
                unsigned long long* depth_range, const BigList& big, cudaStream_t stream,
                const fm::OcclusionMap& occlusion = {});

// After a chunk cull has written live.keep[0, chunks): slot = the exclusive sum of keep, the kept
// chunks into index[] in index order, and count (two launches: a CUB scan, a scatter).
void order_live_chunks(const LiveChunks& live, uint64_t chunks, cudaStream_t stream);
// Scratch bytes order_live_chunks' scan needs over `chunks` chunks (LiveChunks::scan_temp).
std::size_t live_scan_temp_bytes(uint64_t chunks);
// Zeroes out.chunk_total over live.capacity slot chunks (the slot chunks past the kept ones must
// read as empty to the list's count and scan).
void clear_chunk_totals(const Projected& out, const LiveChunks& live, cudaStream_t stream);

// Stage 1, big Gaussians (preprocess.cu): a warp per big Gaussian of `big`, and a block per part
// of a huge one (huge_parts, tile_test.cuh; each part's count into big.part_count), counts the
// tiles of its rectangle (out.rect) passing `tests` into out.tiles_touched (zero on entry), adds them to its chunk's
// out.chunk_total, adds the Gaussians found visible to *visible and, where depth_range is not
// null, widens it by the depths (out.depth) of those with entries.
void count_big_tiles(const BigList& big, const TileTests& tests, const Projected& out, unsigned long long* visible,
                     unsigned long long* depth_range, cudaStream_t stream);

}  // namespace catgs::cuda::stages
