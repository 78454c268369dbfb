// The five stages of the CUDA core, one per .cu file, each mirroring the CPU reference stage of the
// same name (cpu_renderer.h). Raw device pointers and an explicit stream; no ownership here (the
// CudaRenderer owns the buffers). Every launcher checks its launch and throws CudaError.
#pragma once

#include <cstddef>
#include <cstdint>

#include <cuda_runtime.h>
#include <glm/glm.hpp>

#include "speculation/speculation_params.h"

namespace catgs::cuda::stages {

using catgs::TrailWidening;

// The camera as the kernels see it (by value in kernel parameters).
struct CameraParams {
  glm::mat3 R;            // world-to-camera rotation
  glm::vec3 t;            // world-to-camera translation
  glm::vec3 position;     // camera centre, world
  float fx, fy, cx, cy;   // pixels; (cx, cy) in continuous image coordinates
  int width, height;      // pixels
  float near_plane, far_plane;
  glm::vec2 tan_half_fov; // (W / (2 fx), H / (2 fy))
  int tiles_x, tiles_y;
};

// The scene in device memory (layouts of GaussianModel).
struct SceneView {
  const float* means;           // [N, 3]
  const float* log_scales;      // [N, 3]
  const float* rotations;       // [N, 4] (w, x, y, z)
  const float* opacity_logits;  // [N]
  const float* sh;              // [N, K, 3], K = (sh_degree + 1)^2
  int sh_degree;
  uint64_t n;
};

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
// - power_cut = -q_max / 2 - 1e-3: a pixel whose power -q/2 lies below it skips the entry before
//   the exp (blend.cuh blend_entry); +inf at opacity 0, so every pixel skips it.
struct __align__(32) Splat {
  float4 mean_ab;          // (mean.x, mean.y, A, B)
  float4 c_opacity_q_cut;  // (C, opacity, q_max, power_cut)
};

// Stage 1 output, one entry per Gaussian; tiles_touched == 0 marks a culled Gaussian whose other
// fields are left unwritten.
struct Projected {
  Splat* splat;               // [N] 2D mean, conic, opacity, q_max, power cut
  float4* color;              // [N] (r, g, b, unused): 16-byte loads in the rasterizer
  float* depth;               // [N] camera-space z
  ushort4* rect;              // [N] tile rectangle [x0, x1) x [y0, y1)
  uint32_t* tiles_touched;    // [N] render-list entries this Gaussian emits
};

// Gaussians whose candidate rectangle has more than tune::kBigRectTiles tiles, handled a warp
// each: their indices (order arbitrary) and how many there are, both in device memory.
struct BigList {
  uint32_t* index;   // [N] capacity
  unsigned* count;   // [1]
};

// catgs key frames: each visible Gaussian's trail (forward_model.h fm::Trail), pixel units.
struct Trails {
  float4* mean0_motion;  // [N] (mean0.x, mean0.y, motion.x, motion.y)
  float4* conic_q;       // [N] (A, B, C) inverse of the trail covariance, q_trail
  float4* cov;           // [N] (a, b, c, q_trail) trail covariance (sub-frame containment check)
  // [N] Gaussians whose tile rectangle holds at most tune::kBigRectTiles tiles: bit b set when
  // the trail touches the rectangle's b-th tile in row-major order, as counted by the speculative
  // pre-processing, so key emission reads the answers instead of testing every tile again.
  uint32_t* tile_mask;
};

// Which tile test decides render-list membership (the three pipelines' stage 2).
enum class TileTestKind { square, ellipse, trail };

// The inputs of the tile test, read per Gaussian by tile_test.cuh.
struct TileTests {
  TileTestKind kind;
  const Splat* splat;           // [N] ellipse: mean, conic, q_max
  Trails trails;                // trail
  int width, height;            // pixels
};

// The speculation path of a catgs key frame: the key camera, then the predicted cameras of the
// window (paper sec. 3.1), passed by value to the kernel (33 x 108 bytes fits a launch's
// parameter space).
inline constexpr int kMaxPath = 33;
struct PathParams {
  int count;
  CameraParams cam[kMaxPath];
};

// Stage 1 (preprocess.cu): frustum culling, EWA 2D covariance, conic, SH colour, tile bounds and
// per-Gaussian tile counts (vanilla: 3-sigma square; exact: opacity-aware ellipse-vs-tile test).
// Adds the number of visible Gaussians to *visible (one atomic per block). Big Gaussians are
// appended to `big` (one atomic per warp that holds any); with `exact`, their tiles are counted
// by a second kernel, a warp per Gaussian. `big.count` must be zero on entry.
void preprocess(const SceneView& scene, const CameraParams& cam, bool exact, const Projected& out,
                unsigned long long* visible, const BigList& big, cudaStream_t stream);

// Stage 1, big Gaussians (preprocess.cu): a warp per Gaussian of `big` counts the tiles of its
// rectangle passing `tests` into tiles_touched, and adds the Gaussians found visible to *visible.
void count_big_tiles(const BigList& big, const TileTests& tests, const ushort4* rect,
                     uint32_t* tiles_touched, unsigned long long* visible, cudaStream_t stream);

// catgs key frame, stage 1 (speculative_preprocess.cu; mirrors cpu/speculative_preprocess.cpp):
// each Gaussian is projected at every camera of `path`; one visible at the key camera gets the
// key frame's features, a trail (fm::build_trail, widened by `widening`) and the number of
// tiles the trail touches. Big trails are counted by count_big_tiles (called here). A Gaussian
// beyond one same image edge at every camera of the path is culled before any 2D covariance
// (as cpu::speculative_preprocess).
void speculative_preprocess(const SceneView& scene, const PathParams& path, const TrailWidening& widening,
                            const Projected& out, const Trails& trails, unsigned long long* visible,
                            const BigList& big, cudaStream_t stream);

// catgs planner input (speculative_preprocess.cu; mirrors cpu::max_screen_motion): the largest
// screen motion (pixels) between cameras a and b of the means visible in a deeper than
// min_depth, as float bits into *max_bits (which must hold 0 on entry; atomicMax on the bits of
// non-negative floats orders like the floats).
void max_screen_motion(const SceneView& scene, const CameraParams& a, const CameraParams& b,
                       float min_depth, unsigned* max_bits, cudaStream_t stream);

// Frustum cache (subframe_features.cu; paper sec. 3.2): the indices of the Gaussians with
// tiles_touched > 0, increasing, into cached[]; their number into *count (device).
std::size_t select_cached_temp_bytes(uint64_t n);
void select_cached(const uint32_t* tiles_touched, uint64_t n, uint32_t* cached, unsigned* count,
                   void* temp, std::size_t temp_bytes, cudaStream_t stream);

// catgs sub-frame, stage 1 (subframe_features.cu; mirrors cpu::update_subframe_features):
// recomputes the splat (mean, conic, opacity: 0 when culled here) and colour of the `count` cached
// Gaussians at `cam`, and sets *outside = 1 when an on-screen ellipse reaches a tile its trail was
// not listed in (the frame must then be a key frame). *outside must hold 0 on entry.
void update_subframe_features(const SceneView& scene, const CameraParams& cam, const uint32_t* cached,
                              uint32_t count, const Projected& projected, const Trails& trails,
                              unsigned* outside, cudaStream_t stream);

// catgs sub-frame (subframe_features.cu; mirrors cpu::unlisted_reach_image): sets *outside = 1
// when a Gaussian the key frame did not list (tiles_touched == 0) reaches a pixel at `cam`: it is
// outside the frustum cache, so only a key frame can draw it.
void check_unlisted(const SceneView& scene, const CameraParams& cam, const uint32_t* tiles_touched,
                    unsigned* outside, cudaStream_t stream);

// Stage 2a (key_emission.cu): inclusive scan of tiles_touched into 64-bit ends[N] (CUB), then a
// one-thread kernel copies ends[N-1] and *visible into counts[0..1] for one 16-byte readback.
std::size_t scan_temp_bytes(uint64_t n);
void scan_tiles_touched(const uint32_t* tiles_touched, uint64_t* ends, uint64_t n, void* temp,
                        std::size_t temp_bytes, const unsigned long long* visible,
                        unsigned long long* counts, cudaStream_t stream);

// Stage 2a' (depth_order.cu, the depth-first sort): sorts the `visible` Gaussians with
// tiles_touched > 0 by depth (stable, so equal depths keep index order) and rewrites ends[i] of
// each of them as the inclusive running sum of tiles_touched in that order (the others keep
// theirs). Emission then lays each Gaussian's entries out in depth order, and a stable sort on
// the tile alone (sort_pairs_by_tile) gives the [tile | depth] list. `visible` comes from the
// counts readback. Returns the depth order (device, [visible] Gaussian indices; emit_keys walks
// the Gaussians in it, so consecutive threads write consecutive slots). Buffers: index and keys [2][N], count [1], temp of depth_order_temp_bytes(N);
// ends must hold N + 1 entries (a spare slot, see depth_order.cu).
struct DepthOrderBuffers {
  uint32_t* index[2];
  uint32_t* keys[2];
  unsigned* count;
  void* temp;
  std::size_t temp_bytes;
};
std::size_t depth_order_temp_bytes(uint64_t n);
const uint32_t* depth_order_ends(const uint32_t* tiles_touched, const float* depth, uint64_t n, uint64_t visible,
                                 const DepthOrderBuffers& buffers, uint64_t* ends, cudaStream_t stream);

// Stage 2b (key_emission.cu): each Gaussian writes its keys and values (its index) at
// [ends[i] - tiles_touched[i], ends[i]), in row-major tile order; never more than
// tiles_touched[i] entries; slots it cannot fill get the sentinel tile id `tiles` (sorted last,
// ignored later). Big Gaussians are emitted a warp each (ballot + popc keeps the row-major
// order); catgs trails with tile masks a warp per 32 Gaussians of the walk, whose adjacent runs
// the warp writes on consecutive slots (coalesced). Keys go to `keys` as [tile | depth bits]
// (64-bit), or, when `tile_keys` is not null (the depth-first sort), to `tile_keys` as the tile
// id alone (32-bit). `order` (or null: all N
// in index order): the `order_count` Gaussians to walk, in that order (depth_order_ends's).
void emit_keys(const Projected& projected, const uint64_t* ends, uint64_t n, const CameraParams& cam,
               const TileTests& tests, const BigList& big, uint64_t* keys, uint32_t* tile_keys,
               uint32_t* values, const uint32_t* order, uint64_t order_count, cudaStream_t stream);

// Stage 3 (sort.cu): CUB radix sort of (key, value) pairs over the low `key_bits` bits. Sorts
// between the two halves of each double buffer; returns which half holds the result (0 or 1).
// sort_pairs_by_tile: the same on 32-bit tile keys (the depth-first sort's second pass).
std::size_t sort_temp_bytes(uint64_t entries, int key_bits);
int sort_pairs(uint64_t* keys[2], uint32_t* values[2], uint64_t entries, int key_bits, void* temp,
               std::size_t temp_bytes, cudaStream_t stream);
std::size_t sort_by_tile_temp_bytes(uint64_t entries, int key_bits);
int sort_pairs_by_tile(uint32_t* keys[2], uint32_t* values[2], uint64_t entries, int key_bits, void* temp,
                       std::size_t temp_bytes, cudaStream_t stream);

// Stage 4 (tile_ranges.cu): [start, end) of each tile in the sorted list; tiles without entries get
// [0, 0). Sentinel entries (tile id >= tiles) are ignored. Keys are [tile | depth] (64-bit) or,
// with the depth-first sort, tile ids (32-bit).
void tile_ranges(const uint64_t* sorted_keys, uint64_t entries, uint32_t tiles, uint2* ranges,
                 cudaStream_t stream);
void tile_ranges(const uint32_t* sorted_tile_keys, uint64_t entries, uint32_t tiles, uint2* ranges,
                 cudaStream_t stream);

// Stage 4b (tile_ranges.cu): tile ids by decreasing number of entries (a stable radix sort of
// 32-bit loads), so the rasterizer's blocks start on the heaviest tiles and the light ones fill
// in behind them (longest-processing-time-first scheduling) instead of the heavy tiles of the
// bottom rows starting last. scratch: [3 * tiles].
std::size_t tile_order_temp_bytes(uint32_t tiles);
void order_tiles(const uint2* ranges, uint32_t tiles, uint64_t entries, uint32_t* scratch,
                 uint32_t* order, void* temp, std::size_t temp_bytes, cudaStream_t stream);

// Stage 5 (rasterize.cu): one block per tile, front-to-back blending; writes float RGB and packed
// 8-bit RGBA (R | G << 8 | B << 16 | 255 << 24) in device memory. `warp_cull` (exact pipeline
// only: needs q_max) skips, per warp, entries whose ellipse reaches none of the warp's pixels.
// `tile_order` [tiles]: block b rasterizes tile tile_order[b] (null: tile b).
void rasterize(const uint2* ranges, const uint32_t* tile_order, const uint32_t* sorted_values,
               const Projected& projected, const CameraParams& cam, bool warp_cull, float3 background, float* out_rgb,
               uint32_t* out_rgba8, cudaStream_t stream);

// Task splitting (task_split.cu; paper sec. 3.4, supplementary Alg. 1; mirrors cpu::plan_slices):
// with average load avg = max(1, L / tiles), a tile over 2 avg entries becomes load / avg slices
// of avg entries, the first taking the remainder; otherwise (or split = false) one slice.
// Slices are numbered tile by tile, a tile's in list order. Outputs:
//   slice_range [capacity] [begin, end) of each slice; slots past the total get [0, 0)
//   slice_tile  [capacity] (tile, k) of each slice; slots past the total get tile = 0xffffffff
//   tile_plan   [tiles]    (first slice, slice count, first partial slot, 0); a tile of one slice
//                          has no partial slots (its slice writes the image directly)
//   totals      [2]        (slices, partial slots), device
// capacity = slice_capacity(tiles, L, min_slice): tiles + L / avg bounds the slice count, with
// avg = split_average(tiles, L, min_slice) = max(L / tiles, 1, min_slice) the slice length
// (SpeculationParams::min_slice_entries).
//   saturated_from [tiles] reset by rasterize_slices: the first slice of a tile that saturates
//                          it alone (rasterize_slices.cu)
//   slot_finished  [slot_count] reset by rasterize_slices: 1 once the slice of that partial slot
//                          has written its partials (rasterize_slices.cu)
struct SlicePlan {
  uint2* slice_range;
  uint2* slice_tile;
  uint4* tile_plan;
  unsigned* totals;
  unsigned* saturated_from;
  unsigned* slot_finished;
  uint64_t slot_count;  // entries of slot_finished (at least the partial slots of any plan)
};
uint64_t split_average(uint32_t tiles, uint64_t entries, uint64_t min_slice);
uint64_t slice_capacity(uint32_t tiles, uint64_t entries, uint64_t min_slice);
std::size_t plan_slices_temp_bytes(uint32_t tiles);
void plan_slices(const uint2* ranges, uint32_t tiles, uint64_t entries, bool split, uint64_t min_slice,
                 const SlicePlan& plan, uint64_t* scan_scratch, void* temp, std::size_t temp_bytes,
                 cudaStream_t stream);

// The slice order (task_split.cu): slices by k, then by decreasing length (a tile's first slice
// runs before its later ones, and the long ones start first); slots past the total last.
// scratch: [3 * capacity].
std::size_t order_slices_temp_bytes(uint64_t capacity);
void order_slices(const SlicePlan& plan, uint64_t capacity, uint32_t* scratch, uint32_t* order, void* temp,
                  std::size_t temp_bytes, cudaStream_t stream);

// Stage 5 with slices (rasterize_slices.cu; mirrors cpu::rasterize_slices): one block per slice
// (block b takes slice order[b], or b without an order; `blocks` may exceed the slice total: the
// extra blocks return). A tile's only slice writes C + T * background to the image; a slice of a
// split tile writes its partial colour and transmittance to partials [slots, 256] (C.rgb, T).
// `early_termination`: stop a pixel before T would drop below 1e-4 within its slice; a pixel's
// composition ends at the first slice in which it stops or after which its transmittance is
// below 1e-4, so a later slice skips the pixels whose earlier slices, finished before it starts,
// already end it, and a slice behind one that saturated its tile alone is skipped entirely (see
// rasterize_slices.cu: the paper's higher early-termination threshold for later slices). Resets
// saturated_from and slot_finished first. A stopped pixel's partial T is stored negated.
// `tile_culling`: each round blends only the entries whose ellipse reaches the tile at this
// frame's features (blend_range_culled; same image, for lists built for other poses too).
// `abandon` (device, or null): when it holds non-zero at launch, draw nothing (a sub-frame
// that failed its check and will be drawn again as a key frame).
void rasterize_slices(const SlicePlan& plan, const uint32_t* order, uint32_t blocks,
                      const uint32_t* sorted_values, const Projected& projected, const CameraParams& cam,
                      bool early_termination, bool tile_culling, float3 background, const unsigned* abandon,
                      float4* partials, float* out_rgb, uint32_t* out_rgba8, cudaStream_t stream);
// The merge (rasterize_slices.cu): for each split tile, C = sum_k C_k prod_{m<k} T_m, then
// + prod T * background (paper sec. 3.4); with `early_termination`, a pixel's sum ends after the
// first slice in which it stopped or after which prod T < 1e-4 (as cpu::rasterize_slices).
// Nothing when *abandon (if given) is non-zero.
void merge_slices(const SlicePlan& plan, const float4* partials, const CameraParams& cam, bool early_termination,
                  float3 background, const unsigned* abandon, float* out_rgb, uint32_t* out_rgba8,
                  cudaStream_t stream);

// I420 planes in device memory (pitches in bytes), written by rgba8_to_yuv420.
struct Yuv420Pitched {
  uint8_t* y;
  size_t y_pitch;
  uint8_t* u;
  size_t u_pitch;
  uint8_t* v;
  size_t v_pitch;
};

// After stage 5 (yuv420_convert.cu; mirrors rgba_to_yuv420_bt709 of catgs/yuv420.h): the packed
// RGBA8 image [height, width] -> BT.709 limited-range I420 (Y per pixel, Cb/Cr from each 2x2
// mean). width and height must be even. One thread per 2x2 block.
void rgba8_to_yuv420(const uint32_t* rgba8, int width, int height, const Yuv420Pitched& out,
                     cudaStream_t stream);

}  // namespace catgs::cuda::stages
