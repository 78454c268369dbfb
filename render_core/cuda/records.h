// The records the CUDA stages pass each other: the camera and the scene as the kernels see them,
// and the per-Gaussian outputs of pre-processing (stage 1) that later stages read. Raw device
// pointers with their shapes; the CudaRenderer owns the buffers (renderer_state.h).
#pragma once

#include <cstddef>
#include <cstdint>

#include <cuda_fp16.h>
#include <cuda_runtime.h>
#include <glm/glm.hpp>

#include "forward_model/chunk_bounds.h"
#include "forward_model/compact_codes.h"
#include "forward_model/forward_model.h"
#include "forward_model/key_packing.h"
#include "forward_model/lod.h"
#include "forward_model/occlusion.h"
#include "speculation/speculation_params.h"
#include "tunables.h"

namespace catgs::cuda::stages {

using catgs::TrailWidening;

// The camera as the kernels see it (by value in kernel parameters).
struct CameraParams : fm::View {
  glm::vec3 position;  // camera centre, world
  int tiles_x, tiles_y;
};
// The scene in device memory (layouts of GaussianModel).
struct SceneView {
  const float* means;           // [N, 3]
  const float* log_scales;      // [N, 3]        (null in the compact layout)
  const float* rotations;       // [N, 4] (w, x, y, z)   (null in the compact layout)
  const float* opacity_logits;  // [N]           (null in the compact layout)
  const __half* sh;             // [N, K, 3], K = (sh_degree + 1)^2, binary16 (forward_model/sh_storage.h)
  int sh_degree;
  uint64_t n;
  const fm::ChunkBounds* chunks;  // [chunk_count(N)] (forward_model/chunk_bounds.h)
  const fm::LodNode* lod;         // [chunk_count(N)] (forward_model/lod.h), nullptr: no LOD
  float lod_error_px;             // the cut's bound, pixels (RenderOptions::lod_error_px)
  // The compact layout (issue 74; DeviceScene::compact): the codes of forward_model/compact_codes.h
  // in place of log_scales, rotations, opacity_logits and sh, decoded where a Gaussian is read
  // (scene_fields.cuh). rotation_codes null: the float layout above.
  const uint32_t* rotation_codes;  // [N]
  const uint32_t* scale_codes;     // [N]
  const uchar4* colour_codes;      // [N]: DC red, green, blue codes, alpha code
  const uint8_t* sh_codes;         // [N, sh_code_bytes]
  uint32_t sh_code_bytes;
  const fm::ChunkRanges* ranges;  // [chunk_count(N)]
  const float* opacity_lut;       // [256] the opacity logit of each alpha code
};

// Is chunk c in the scene's LOD cut at view `at` (fm::lod_chunk_drawn; every chunk without LOD)?
// A chunk outside it is skipped as a culled chunk is: another level draws its Gaussians.
CATGS_HD bool lod_drawn(const SceneView& scene, uint64_t c, const fm::View& at) {
  return scene.lod == nullptr || fm::lod_chunk_drawn(scene.lod, c, at, scene.lod_error_px);
}

// One Gaussian's footprint on the image at this frame: everything a rasterizer reads of a
// render-list entry except its colour, packed in one 32-byte record (one DRAM sector, as the
// allocation is 256-byte aligned). A rasterizer gathers each entry's record by its Gaussian index
// (a random access), so separate mean, conic and q_max arrays cost two or three sectors per entry
// where this costs one; the tile cull of a catgs trail list (blend.cuh) reads only this, and the
// colour only for the entries it keeps. Written by splat.cuh make_splat.
// - mean: pixel units (continuous image coordinates, pixel centres at integers).
// - conic (A, B, C): the inverse 2D covariance, q = A dx^2 + 2B dx dy + C dy^2 (paper eq. 2-3).
// - q_max = 2 ln(255 opacity) (fm::opacity_aware_qmax): alpha >= 1/255 iff q <= q_max; -inf at
//   opacity 0 (a Gaussian culled at a sub-frame's pose).
// - log2_opacity = log2(opacity): the rasterizers blend alpha = 2^(log2_opacity + log2(e) power)
//   (blend.cuh blend_entry), opacity folded into the exponent; -inf at opacity 0.
struct __align__(32) Splat {
  float4 mean_ab;           // (mean.x, mean.y, A, B)
  float4 c_opacity_q_log2;  // (C, opacity, q_max, log2_opacity)
};

// Stage 1 output, one entry per slot and one per slot chunk (issue 61: the frame's buffers follow
// the view, not the scene). Stage 1 culls whole chunks of fm::kChunkSize Gaussians first and
// lists those it keeps in index order (LiveChunks); the k-th kept chunk's Gaussians take slots
// [k * kChunkSize, (k + 1) * kChunkSize) of every per-Gaussian buffer, so the buffers hold the
// chunks a view keeps (its frustum and LOD cut), not the scene. Slot order is Gaussian index order
// over the kept chunks, so every order a stage derives from slots (emission, the sort's ties, the
// depth-first order) is the one the CPU reference derives from Gaussian indices. [S] below: slots
// (slot chunks x kChunkSize); [SC]: slot chunks. tiles_touched == 0 marks a culled Gaussian
// whose other fields are left unwritten; a slot chunk past the kept ones has chunk_total 0 (read
// tiles_touched through listed_tiles).
struct Projected {
  Splat* splat;             // [S] 2D mean, conic, opacity, q_max, log2(opacity)
  float4* color;            // [S] (r, g, b, unused): 16-byte loads in the rasterizer
  float* depth;             // [S] camera-space z
  ushort4* rect;            // [S] tile rectangle [x0, x1) x [y0, y1)
  uint32_t* tiles_touched;  // [S] render-list entries this Gaussian emits (0 past the scene's end)
  // [S] exact pre-processing, Gaussians whose rectangle holds at most tune::kBigRectTiles tiles:
  // bit b set when the ellipse reaches the rectangle's b-th tile in row-major order, as counted,
  // so key emission reads the answers instead of testing every tile again (as Trails::tile_mask).
  uint32_t* tile_mask;
  // [SC] the sum of tiles_touched over each slot chunk (its render-list entries): the list scan
  // runs over slot chunks, and later stages skip one with none without reading its Gaussians.
  uint32_t* chunk_total;
};

// Slot s's render-list entries (0 in a slot chunk with none).
__device__ __forceinline__ uint32_t listed_tiles(const uint32_t* tiles_touched, const uint32_t* chunk_total,
                                                 uint64_t s) {
  return chunk_total[s / fm::kChunkSize] != 0u ? tiles_touched[s] : 0u;
}

// The slot chunks a frame's per-Gaussian stages walk, a block per slot chunk: k from 0 to
// size(), scene chunk chunk(k). Pre-processing culls whole chunks first (exact:
// cull_chunks_kernel, preprocess.cu; catgs key frames: cull_path_chunks_kernel,
// speculative_preprocess.cu) and lists those left in index order (order_live_chunks); the other
// stages then launch at most tune::kChunkWalkBlocks blocks over that list, so a culled chunk
// costs a few bytes, not a block and a write per Gaussian (issue 19: "cull whole chunks first").
// A null `index` walks every chunk, slot chunk k = chunk k (no stage asks for that now: both
// pre-processings list).
struct ChunkWalk {
  const uint32_t* index;  // [chunks] or null
  const unsigned* count;  // [1] device: the chunks in index[]
  uint64_t chunks;        // the slot chunks the buffers hold: the most a walk covers
  __device__ uint64_t size() const {
    if (!index) return chunks;
    const uint64_t n = *count;
    return n < chunks ? n : chunks;
  }
  __device__ uint64_t chunk(uint64_t k) const { return index ? index[k] : k; }
  // Blocks of a launch that walks the chunks a block each (grid-stride past the cap).
  uint64_t blocks() const {
    return index ? (chunks < tune::kChunkWalkBlocks ? chunks : tune::kChunkWalkBlocks) : chunks;
  }
};

// Where stage 1 lists the chunks it keeps. Chunk culling writes keep[c]; order_live_chunks
// (preprocess.cu) turns that into slot[c] (the exclusive sum of keep: chunk c's slot chunk where
// kept), index[] (the kept chunks in index order) and count. A frame whose count passes
// `capacity` (the slot chunks its buffers hold) pre-processes only the first `capacity` and is
// drawn again once the buffers grew (CudaRenderer::State::count_render_list).
struct LiveChunks {
  uint32_t* index;    // [chunk_count(N)]
  unsigned* count;    // [1]
  uint32_t* keep;     // [chunk_count(N)]
  uint32_t* slot;     // [chunk_count(N)]
  uint64_t capacity;  // slot chunks
  void* scan_temp;    // the keep -> slot scan's scratch (live_scan_temp_bytes)
  std::size_t scan_temp_bytes;
  ChunkWalk walk() const { return {index, count, capacity}; }
};

// Render-list sort keys (forward_model/key_packing.h): 64-bit plain [tile | depth bits], or the
// 32-bit [tile | quantised depth] of the single sort.
using fm::DepthKeyPacking;

// Gaussians whose candidate rectangle has more than tune::kBigRectTiles tiles, handled a warp
// each, and huge ones (over tune::kHugeRectTiles), a block per part: their indices (order
// arbitrary) and how many there are, all in device memory.
struct BigList {
  uint32_t* index;       // [capacity]: big ones from index[0] up, huge ones from index[capacity - 1] down
  unsigned* count;       // [2]: big ones (not huge), huge ones
  uint64_t capacity;     // S
  uint32_t* part_count;  // [tune::kHugeListed * tune::kHugeParts]: entries of each part of a huge one
  __device__ uint32_t huge(unsigned h) const { return index[capacity - 1 - h]; }
};

// catgs key frames: each visible Gaussian's trail (forward_model/trail.h fm::Trail), pixel units.
struct Trails {
  float4* mean0_motion;  // [S] (mean0.x, mean0.y, motion.x, motion.y)
  float4* conic_q;       // [S] (A, B, C) inverse of the trail covariance, q_trail
  float4* cov;           // [S] (a, b, c, q_trail) trail covariance (sub-frame containment check)
  // [S] Gaussians whose tile rectangle holds at most tune::kBigRectTiles tiles: bit b set when
  // the trail touches the rectangle's b-th tile in row-major order, as counted by the speculative
  // pre-processing, so key emission reads the answers instead of testing every tile again.
  uint32_t* tile_mask;
};

// Which tile test decides render-list membership (the three pipelines' stage 2).
enum class TileTestKind { square, ellipse, trail };

// The inputs of the tile test, read per Gaussian by tile_test.cuh.
struct TileTests {
  TileTestKind kind;
  const Splat* splat;  // [S] ellipse: mean, conic, q_max
  Trails trails;       // trail
  int width, height;   // pixels
};

// The speculation path of a catgs key frame: the key camera, then the predicted cameras of the
// window (paper sec. 3.1), passed by value to the kernel (kMaxPathCameras x 108 bytes fits a
// launch's parameter space).
struct PathParams {
  int count;
  CameraParams cam[kMaxPathCameras];
};
static_assert(sizeof(PathParams) <= 4096, "a kernel's parameters must fit 4 KiB");

}  // namespace catgs::cuda::stages
