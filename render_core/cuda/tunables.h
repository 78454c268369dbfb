// Tunables of the CUDA render core, in one place, with the constraints that tie them together.
#pragma once

#include <cstdint>

#include "camera/camera.h"
#include "forward_model/forward_model.h"

namespace catgs::cuda::tune {

// Rasterizer: one block per 16 x 16 tile, one thread per pixel.
inline constexpr int kTileSize = fm::kTileSize;
inline constexpr int kRasterThreads = kTileSize * kTileSize;
// Gaussians fetched into shared memory per round of the rasterizer (one per thread).
inline constexpr int kRasterBatch = kRasterThreads;
// Each warp of a rasterizer block owns one 8 x 4 sub-tile of the tile (blend.cuh pixel_in_tile):
// 2 columns x 4 rows of sub-tiles, warp w at column w % 2, row w / 2. A warp blends only the
// entries whose ellipse's bounding box reaches its sub-tile (blend.cuh subtile_mask).
inline constexpr int kSubTileW = 8;
inline constexpr int kSubTileH = 4;
inline constexpr int kSubTilesX = kTileSize / kSubTileW;
inline constexpr int kSubTilesY = kTileSize / kSubTileH;

// Threads per block of the per-Gaussian (pre-processing, key emission) and per-entry kernels.
inline constexpr int kGaussianThreads = 256;
inline constexpr int kEntryThreads = 256;
// Grid-stride kernels over the render list launch at most this many blocks (a list can pass 2^31).
inline constexpr unsigned kMaxEntryBlocks = 65535u * 8u;

// Largest image side the renderer accepts (validate_camera) and the tile grid that follows.
inline constexpr int kMaxImageSide = catgs::kMaxImageSide;
inline constexpr int kMaxTilesPerSide = (kMaxImageSide + kTileSize - 1) / kTileSize;

// A Gaussian whose candidate tile rectangle holds more than this many tiles is "big": its tiles
// are counted (exact) and its keys emitted by a whole warp, 32 tiles at a time, instead of by one
// thread in a serial loop. A few huge near Gaussians would otherwise hold their warps (and the
// kernel's tail) for thousands of iterations.
inline constexpr int kBigRectTiles = 32;
// Grid of the big-Gaussian kernels (they loop over a device-side count).
inline constexpr int kBigBlocks = 1024;
inline constexpr int kBigThreads = 256;
// A big Gaussian whose rectangle holds more than this many tiles is "huge": the big-Gaussian
// kernels hand it a whole block (kBigThreads tiles a round) after their warp-per-Gaussian pass,
// in the same launch, instead of a warp: a near Gaussian that spans thousands of tiles held its
// warp for hundreds of rounds while the rest of the GPU idled
// (docs/history/render_core_profiles.md, "A tumblewood exact frame after half-precision SH": the
// ncu figures).
inline constexpr int kHugeRectTiles = kBigThreads;
// A huge Gaussian's rectangle is cut into up to kHugeParts parts of about kHugePartTiles tiles
// (row-major runs), a block each, so that the frame's largest Gaussians (thousands of tiles near
// the camera) do not hold one block for dozens of rounds while the rest of the GPU idles. The
// first kHugeListed huge Gaussians of a frame are cut (their parts' counts are kept for key
// emission: BigList::part_count); any beyond take a block each.
inline constexpr int kHugeParts = 16;
inline constexpr int kHugePartTiles = 2 * kBigThreads;
inline constexpr int kHugeListed = 16384;

// Blocks per SM the rasterizers (rasterize.cu, rasterize_slices.cu) are built for: 8 x 256
// threads fill an SM at 32 registers. The tile-culled slice kernel wants more and spills at 32,
// which cost less than the occupancy gained (docs/history/render_core_rasterizer.md, "The slice
// rasterizer at 8 blocks per SM"); the sub-tile walk (blend.cuh) made every rasterizer want a few
// more (the same file, "Sub-tile rasterization").
inline constexpr int kRasterMinBlocks = 8;
// Blocks per SM of the kernels that loop over a speculation path per Gaussian (the speculative
// pre-processing) and of the sub-frame features kernel: 4 x 256 threads, so at most 64 registers.
// Both are compute- or DRAM-bound with long per-thread state; at 72 registers (3 blocks) each was
// slower (docs/history/render_core_speculation.md, "FMA in the speculative pre-processing; ..." and
// "A sub-frame cull; ...").
inline constexpr int kPathKernelMinBlocks = 4;
// Blocks per SM the exact pre-processing kernel is built for: 5 x 256 threads, so at most 51
// registers (unbounded it takes more and fits 3 blocks). The city's pre-processing, which reads
// every Gaussian of a 7 M scene a frame, gained from the occupancy; 6 blocks spilled more and
// lost it again (docs/history/render_core_sort_and_keys.md, "32-bit sort offsets, key emission past
// big runs, pre-processing at 5 blocks per SM").
inline constexpr int kPreprocessMinBlocks = 5;
inline constexpr int kSubframeFeaturesMinBlocks = 4;

// Most blocks of a launch that walks the chunks exact pre-processing kept (records.h ChunkWalk):
// about 4 waves of 8 blocks on 132 SMs. The list's length is known only on the device, so the
// launch is sized for the most it could hold and blocks stride over it; a cap keeps a scene of
// millions of culled chunks from paying a block launch per chunk.
inline constexpr uint64_t kChunkWalkBlocks = 4096;

// Reusable buffers grow to this multiple of the size asked for, so a trace whose render list
// creeps upwards does not reallocate every frame.
inline constexpr double kGrowthFactor = 1.25;

static_assert(kRasterThreads == 256, "rasterizer assumes 16 x 16 tiles and 256-thread blocks");
static_assert(kRasterBatch == kRasterThreads, "each thread fetches exactly one Gaussian per round");
static_assert(kRasterThreads % 32 == 0, "rasterizer blocks are whole warps");
static_assert(kSubTileW * kSubTileH == 32 && kSubTilesX * kSubTilesY * 32 == kRasterThreads,
              "one sub-tile per warp, covering the tile");
static_assert(kSubTilesX == 2 && kSubTileW == 8, "pixel_in_tile maps lanes and warps with shifts and masks");
static_assert(kMaxTilesPerSide <= 65535, "tile rectangles are stored as ushort4");
static_assert(static_cast<uint64_t>(kMaxTilesPerSide) * kMaxTilesPerSide < (1ull << 32),
              "tile ids (and the sentinel) must fit the 32 key bits above the depth");
static_assert(kGaussianThreads % 32 == 0 && kEntryThreads % 32 == 0 && kBigThreads % 32 == 0, "blocks are whole warps");
static_assert(kBigRectTiles >= 1, "big Gaussians have more tiles than one thread handles well");
static_assert(kBigRectTiles <= 32, "a small Gaussian's trail tiles fit one 32-bit mask (Trails::tile_mask)");
static_assert(kRasterMinBlocks * kRasterThreads <= 2048, "an SM holds at most 2048 threads");
static_assert(kPreprocessMinBlocks * kGaussianThreads <= 2048, "an SM holds at most 2048 threads");
static_assert(kPathKernelMinBlocks * kGaussianThreads * 64 <= 65536, "64 registers a thread fit the SM's file");

}  // namespace catgs::cuda::tune
