// Stage 2 of the CUDA core (key_emission.cu; mirrors cpu/key_emission.cpp).
// Raw device pointers and an explicit stream; every launcher checks its launch (CudaError).
#pragma once

#include <cstddef>
#include <cstdint>

#include "records.h"

namespace catgs::cuda::stages {

// Every n below is the frame's slots (records.h Projected: its slot chunks x fm::kChunkSize), and
// a "chunk" a slot chunk.
// Stage 2a (key_emission.cu): the list length, the sum of the chunks' entry counts
// (Projected::chunk_total), into counts[0] (zeroed by the caller) and *visible into counts[1], for
// the frame's one readback; a few blocks of a grid-stride sum, so the readback can start before
// the scan below, which runs while the host waits for it.
void count_list(const Projected& projected, uint64_t n, const unsigned long long* visible, unsigned long long* counts,
                cudaStream_t stream);
// Stage 2a (key_emission.cu): exclusive scan of the chunks' entry counts into 64-bit
// chunk_start[chunk_count(n)] (CUB).
std::size_t scan_temp_bytes(uint64_t chunks);
void scan_chunks(const Projected& projected, uint64_t n, uint64_t* chunk_start, void* temp, std::size_t temp_bytes,
                 cudaStream_t stream);
// Stage 2a' (key_emission.cu): ends[i], the end of Gaussian i's run in the list in index order
// (its chunk's start + the inclusive sum of tiles_touched within the chunk), a block per chunk of
// `walk` (records.h ChunkWalk: the chunks pre-processing kept); left unwritten in chunks without
// entries, which emission in index order skips.
void gaussian_ends(const Projected& projected, uint64_t n, const ChunkWalk& walk, const uint64_t* chunk_start,
                   uint64_t* ends, cudaStream_t stream);

// Stage 2b (key_emission.cu): each Gaussian writes its keys and values (its index) at
// [ends[i] - tiles_touched[i], ends[i]), in row-major tile order; never more than
// tiles_touched[i] entries; slots it cannot fill get the sentinel tile id `tiles` (sorted last,
// ignored later). Big Gaussians are emitted a warp each (ballot + popc keeps the row-major
// order); catgs trails with tile masks a warp per 32 Gaussians of the walk, whose adjacent runs
// the warp writes on consecutive slots (coalesced). Keys are made as `packing` says
// (forward_model/key_packing.h): 64-bit into `wide_keys`, or, when `narrow_keys` is not null,
// 32-bit into it (the single sort's [tile | quantised depth]; the tile id alone for the
// depth-first sort). `order` (or null: the Gaussians of the chunks of `chunks`, skipping chunks
// without entries): the `order_count` Gaussians to walk, in that order (depth_order_ends's).
void emit_keys(const Projected& projected, const uint64_t* ends, uint64_t n, const ChunkWalk& chunks,
               const CameraParams& cam, const TileTests& tests, const BigList& big, uint64_t* wide_keys,
               uint32_t* narrow_keys, DepthKeyPacking packing, uint32_t* values, const uint32_t* order,
               uint64_t order_count, cudaStream_t stream);

}  // namespace catgs::cuda::stages
