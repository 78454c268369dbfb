// The CPU reference renderer: the forward model of forward_model.h as five stages, one per file
// under cpu/, mirroring the CUDA core stage for stage:
//   preprocess -> emit_keys -> sort_render_list -> identify_tile_ranges -> rasterize
// Multi-threaded over Gaussians and tiles; deterministic (the same input gives the same bits).
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <vector>

#include <glm/glm.hpp>

#include "forward_model/chunk_bounds.h"
#include "forward_model/occlusion.h"
#include "forward_model/lod.h"
#include "forward_model/forward_model.h"
#include "forward_model/key_packing.h"
#include "speculation/speculation_planner.h"
#include "renderer/renderer.h"

namespace catgs::cpu {

// Stage times of the CPU core: wall clock, milliseconds.
using clock = std::chrono::steady_clock;
inline double ms_between(clock::time_point a, clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

// The tile grid of an image: ceil(W / 16) x ceil(H / 16) tiles, row-major tile ids.
struct TileGrid {
  int width = 0, height = 0;     // pixels
  int tiles_x = 0, tiles_y = 0;  // tiles
  static TileGrid of(int width, int height) {
    return {width, height, (width + fm::kTileSize - 1) / fm::kTileSize, (height + fm::kTileSize - 1) / fm::kTileSize};
  }
  int tile_count() const { return tiles_x * tiles_y; }
};

// Stage 1 output, one entry per scene Gaussian (N). A Gaussian with tiles_touched == 0 is culled
// and its other fields are unspecified.
struct ProjectedGaussians {
  std::vector<glm::vec2> mean2d;        // [N] pixel units (pixel (i, j) centre at (i, j))
  std::vector<glm::vec3> conic;         // [N] inverse 2D covariance (A, B, C), 1/px^2
  std::vector<float> opacity;           // [N] sigmoid(logit), (0, 1)
  std::vector<float> depth;             // [N] camera-space z, world units
  std::vector<float> q_max;             // [N] exact pipeline: alpha >= 1/255 iff q <= q_max
  std::vector<glm::vec3> color;         // [N] RGB from SH (+0.5, >= 0)
  std::vector<fm::TileRect> tile_rect;  // [N] tiles to test, [x0, x1) x [y0, y1)
  std::vector<uint32_t> tiles_touched;  // [N] render-list entries this Gaussian emits
  // catgs key frames: the trail (forward_model/trail.h fm::Trail) the tile test uses, pixel units.
  std::vector<glm::vec2> trail_mean0;   // [N] projected mean at the key frame
  std::vector<glm::vec2> trail_motion;  // [N] to the end of the window
  std::vector<glm::vec3> trail_cov;     // [N] dominating 2D covariance
  std::vector<glm::vec3> trail_conic;   // [N] its inverse
  std::vector<float> q_trail;           // [N] level
  // Occlusion culling's per-entry test (forward_model/occlusion.h entry_hidden), exact frames with
  // a map: the frame's reprojected map (its cells, owned by the renderer; cells[0] null: none),
  // applied to the Gaussians of at most fm::kOcclusionEntryTiles tiles.
  fm::OcclusionMap occlusion;
  std::size_t chunks_kept = 0;  // chunks pre-processed (the cut's, less those chunk culling dropped)
  void resize(std::size_t n);
};

// The render list: (key, value) pairs, key = [tile | depth] as `packing` makes it
// (forward_model/key_packing.h), value = Gaussian index.
struct RenderList {
  std::vector<uint64_t> keys;     // [L] made as `packing` says: emission writes plain keys, the sort re-keys
  std::vector<uint32_t> values;   // [L]
  std::vector<uint64_t> offsets;  // [N] exclusive prefix sum of tiles_touched (emission offsets)
  fm::DepthKeyPacking packing = fm::plain_key_packing();  // forward_model/key_packing.h
};

// Tile ranges: [start, end) of each tile's entries in the sorted render list.
using TileRanges = std::vector<glm::uvec2>;  // [tiles]

// Stage 1 (cpu/preprocess.cpp): frustum culling (z < near), 3D -> 2D covariance (EWA), conic,
// SH colour, tile bounds and the number of tiles each Gaussian reaches: vanilla counts every tile of
// its 3-sigma square; exact counts the tiles passing fm::ellipse_touches_tile (opacity-aware).
// exact first skips whole chunks that cannot reach the image (`chunks`: chunk_bounds_of(model),
// forward_model/chunk_bounds.h); the result is the same with or without that step.
// `region`: one pass of a frame drawn in passes (renderer/render_passes.h) counts only the tiles
// of its region (fm::clip_tile_rect; every Gaussian is projected with the whole camera).
// A scene with LOD (model.lod) projects only the chunks of its cut at `camera` with bound
// `lod_error_px` (fm::lod_chunk_drawn; 0: the leaves), in every pipeline; the others are skipped
// as culled chunks are. exact also drops the entries that `occlusion` (the last frame's map
// reprojected onto this frame, occlusion_reproject; no cells: none) hides: chunks whole
// (fm::chunk_hidden) and a small Gaussian's each entry (fm::entry_hidden; emit_keys drops the
// same); issue 72.
void preprocess(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks, const Camera& camera,
                Pipeline pipeline, ProjectedGaussians& out, const fm::TileRect& region = fm::kAllTiles,
                float lod_error_px = 0.0f, const fm::OcclusionMap& occlusion = {});

// catgs key frame, stage 1 (cpu/speculative_preprocess.cpp; paper sec. 3.1): `path` holds the
// key camera and the predicted cameras of the window (W + 1 >= 1). Each Gaussian is projected at
// every camera of the path; those visible at the key camera get the key frame's features (as
// preprocess) and a trail holding their ellipse at each (fm::build_trail, widened by `widening`),
// and count the tiles their trail touches (fm::trail_touches_tile). Before any 2D covariance, a
// Gaussian that lies beyond one same image edge at every camera of the path, by more than
// fm::edges_beyond's bound widened as its trail would be, is culled (touches no tile). Before
// that, whole chunks (`chunks`: fm::chunk_bounds of the model) that fm::chunk_misses_path culls
// are skipped, as the CUDA core does; the result is the same with or without that step.
// A scene with LOD takes the cut at the key camera (path.front(), bound `lod_error_px`) for the
// whole window, so every sub-frame draws the Gaussians its key frame listed.
void speculative_preprocess(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks,
                            const std::vector<Camera>& path, const TrailWidening& widening, ProjectedGaussians& out,
                            float lod_error_px = 0.0f);

// catgs planner input: the largest screen motion (pixels) between cameras `a` and `b` of the
// means of Gaussians visible in `a` deeper than `min_depth` (paper sec. 3.1, M). Chunks none of
// whose means can count (fm::chunk_means_off_image, `chunks` as chunk_bounds_of(model)) are
// skipped, as the CUDA core does; the result is the same with or without that step. Throws
// std::invalid_argument for chunk bounds of another scene. With LOD, only the chunks of the cut
// at `a` (bound `lod_error_px`) count.
float max_screen_motion(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks, const Camera& a,
                        const Camera& b, float min_depth, float lod_error_px = 0.0f);

// catgs sub-frame (cpu/subframe_features.cpp; paper sec. 3.2): recomputes mean2d, conic,
// opacity and colour of the cached Gaussians at `camera` (opacity 0 for one culled there; the
// key frame's colour kept with `key_colour`: SpeculationParams::subframe_key_colour) and
// checks that each on-screen ellipse reaches only tiles its trail was listed in (fm::trail_contains,
// else the exact fm::listed_tiles_cover). Returns false when one does not: the frame must be
// rendered as a key frame.
// Also false when unlisted_reach_image() (`key_cut`: the key frame's LOD cut, passed on).
bool update_subframe_features(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks,
                              const Camera& camera, const std::vector<uint32_t>& cached, ProjectedGaussians& projected,
                              bool key_colour = false, const fm::LodCut& key_cut = {});

// catgs sub-frame (cpu/subframe_features.cpp): does a Gaussian the key frame did not list
// (tiles_touched == 0) reach a pixel at `camera` (fm::unlisted_reaches_image)? Such a Gaussian is
// outside the frustum cache, so the sub-frame would miss it: the frame must be a key frame
// (docs/DESIGN.md "Speculation" 2: prediction error must never show as holes). Chunks outside the
// view (fm::chunk_outside_view over `chunks`, chunk_bounds_of(model)) hold none and are skipped,
// and so are the chunks outside the key frame's LOD cut `key_cut` (their Gaussians are drawn by
// another level; the default draws every chunk, right for a scene without LOD only).
bool unlisted_reach_image(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks, const Camera& camera,
                          const ProjectedGaussians& projected, const fm::LodCut& key_cut = {});

// Task splitting (cpu/task_split.cpp; paper sec. 3.4): slices of the tile ranges, in tile
// order, a tile's slices consecutive and in list order. split = false: one slice per tile.
// min_slice: the slice length's floor (SpeculationParams::min_slice_entries; 0: the paper's l).
// The slice length l = list_length / ranges.size(): a pass of a frame drawn in passes gives the
// whole frame's list length, so its tiles split as in one pass, and plans only tiles
// [first_tile, end_tile).
void plan_slices(const TileRanges& ranges, std::size_t list_length, bool split, std::vector<TileSlice>& slices,
                 std::size_t min_slice = 0, std::uint32_t first_tile = 0, std::uint32_t end_tile = UINT32_MAX);

// Stage 5 with slices (cpu/rasterize_slices.cpp): each slice blends its entries into a partial
// colour C_k and transmittance T_k per pixel (early termination within the slice if enabled); the
// merge composes C = sum_k C_k prod_{m<k} T_m, then adds prod T * background (paper sec. 3.4).
// With early_termination a pixel's sum ends after the first slice in which it stopped or after
// which prod T < 1e-4, as the CUDA merge does (its later slices weigh under 1e-4: the paper's
// higher threshold for later slices). `slices`: [begin, end) runs of `list`, a tile's slices
// consecutive and in list order (plan_slices); `out` becomes grid.width x grid.height (linear RGB
// floats and RGBA8); `merge_ms`, if given, receives the merge's wall time in milliseconds.
// Writes only tiles [first_tile, end_tile) (a pass of a frame drawn in passes; `out` keeps the
// other passes' tiles). `tile_opaque_at` (null, or [grid.tile_count()]): those tiles' opaque point
// P (forward_model/occlusion.h: the list position by which every pixel of the tile had stopped or
// fallen below fm::kOcclusionTransmittance; UINT32_MAX where a pixel never did), as the CUDA
// core's rasterize_slices writes it; `pixel_depth` (null, or [grid pixels], with tile_opaque_at):
// per pixel of those tiles the view depth of the entry before its own opaque point (+inf where it
// has none): the per-pixel map (forward_model/occlusion.h). `changed` (null, or [list length]): blend_tile's measurement
// of the entries that change a pixel (meaningful for tiles of one slice: a later slice starts its
// own transmittance at 1).
void rasterize_slices(const ProjectedGaussians& projected, const RenderList& list, const std::vector<TileSlice>& slices,
                      const TileGrid& grid, bool early_termination, glm::vec3 background, Image& out,
                      double* merge_ms = nullptr, std::uint32_t first_tile = 0, std::uint32_t end_tile = UINT32_MAX,
                      std::uint32_t* tile_opaque_at = nullptr, std::uint8_t* changed = nullptr,
                      float* pixel_depth = nullptr);

// The occlusion map (cpu/occlusion_map.cpp; mirrors cuda/occlusion_map.cu): for tiles
// [first_tile, end_tile), the depth of the entry before each tile's opaque point P
// (rasterize_slices' tile_opaque_at) into tile_depth, +inf where P is UINT32_MAX. Returns the
// render-list entries at or behind P over those tiles (FrameStats::entries_behind_opaque).
std::uint64_t occlusion_map(const ProjectedGaussians& projected, const RenderList& list, const TileRanges& ranges,
                            const std::uint32_t* tile_opaque_at, std::uint32_t first_tile, std::uint32_t end_tile,
                            float* tile_depth);

// Issue 72's bound on occlusion tests before pre-processing (cpu/hidden_count.cpp): adds to
// stats' gaussians_preprocessed, gaussians_in_hidden_chunks, gaussians_in_hidden_groups,
// gaussians_hidden_alone and entries_hidden_pixels for the frame just drawn (one pass:
// `projected`, `list` and `ranges` of the whole frame).
void count_hidden(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks, const Camera& camera,
                  float lod_error_px, const ProjectedGaussians& projected, const RenderList& list,
                  const TileRanges& ranges, FrameStats& stats);

// The last frame's per-pixel map (`last_pixels`, drawn at `last`) reprojected onto `now`
// (cpu/occlusion_map.cpp; mirrors cuda/occlusion_map.cu): fm::occlusion_quad of every 2 x 2 block
// of last's pixels drawn with a depth test into `now_pixels` ([now's pixels], +inf where none
// covers), then the deepest per cell into `cells` (fm::occlusion_cells' layout). Returns the map.
fm::OcclusionMap occlusion_reproject(const float* last_pixels, const fm::View& last, const fm::View& now,
                                     std::vector<float>& now_pixels, std::vector<float>& cells);

// Stage 2 (cpu/key_emission.cpp): exclusive scan of tiles_touched, then each Gaussian writes
// its keys at its offset (same order as the GPU: Gaussian index, then tile row-major). catgs uses
// the trail test, exact the ellipse test, vanilla every tile of the rectangle.
// Throws RenderBudgetError past `budget` (renderer.h, with kBytesPerListEntry) and
// std::length_error past 2^32 - 1 entries (values and ranges are 32-bit), before allocating.
void emit_keys(const ProjectedGaussians& projected, const TileGrid& grid, Pipeline pipeline,
               const RenderListBudget& budget, RenderList& list);

// The list length a pre-processed frame (or pass) will emit: the sum of tiles_touched
// (cpu/key_emission.cpp), which the renderers hold against the budget before emit_keys.
std::uint64_t count_entries(const ProjectedGaussians& projected);

// Host bytes a render-list entry takes: its key (8) and value (4), and the sort's (key, value)
// pair (16 with padding).
inline constexpr std::uint64_t kBytesPerListEntry = 28;

// Stage 3 (cpu/sort.cpp): re-keys the list's plain keys as `packing` says and sorts it by key;
// equal keys keep emission order (a stable radix sort on the GPU). Sets list.packing.
void sort_render_list(RenderList& list, const fm::DepthKeyPacking& packing);

// The single sort's key for a list of plain keys on `grid` (fm::single_sort_packing over the
// depth range of its entries), as the CUDA core works it out from pre-processing: exact and
// vanilla frames sort with it; catgs key frames with the plain key (the GPU sorts them depth
// first).
fm::DepthKeyPacking single_sort_packing_of(const RenderList& list, const TileGrid& grid);

// The single sort's key of the list a pre-processed frame will emit, from the depths of its
// Gaussians with entries (the same as single_sort_packing_of that list): a frame drawn in passes
// sorts every pass with its whole frame's key, so each tile's order is the single pass's.
fm::DepthKeyPacking single_sort_packing_of(const ProjectedGaussians& projected, const TileGrid& grid);

// Stage 4 (cpu/tile_ranges.cpp): tile ranges of a sorted list; tiles without entries get
// [0, 0).
void identify_tile_ranges(const RenderList& list, const TileGrid& grid, TileRanges& ranges);

// Stage 5 (cpu/rasterize.cpp): front-to-back alpha blending per pixel over its tile's range
// (paper eq. 3): alpha = min(0.99, opacity * exp(power)), skipped below 1/255, a pixel stops
// before the Gaussian that would take T below 1e-4; C + T * background. Fills out.rgb and
// out.rgba8 at grid size; only tiles [first_tile, end_tile) are written (as rasterize_slices).
void rasterize(const ProjectedGaussians& projected, const RenderList& list, const TileRanges& ranges,
               const TileGrid& grid, glm::vec3 background, Image& out, std::uint32_t first_tile = 0,
               std::uint32_t end_tile = UINT32_MAX);

// Stage 5b (cpu/depth_grid.cpp; forward_model/depth_grid.h): the frame's depth grid with a vertex
// every `cell` pixels, from the sorted list's tile ranges; only vertices whose pixel lies in
// tiles [first_tile, end_tile) are written (a pass's); `out` is reshaped (to +inf) when its shape
// differs.
void depth_grid(const ProjectedGaussians& projected, const RenderList& list, const TileRanges& ranges,
                const TileGrid& grid, int cell, std::uint32_t first_tile, std::uint32_t end_tile, DepthGrid& out);

// A whole frame through the exact or vanilla stages, as both renderers draw it (CpuRenderer's
// frames, SpeculativeRenderer's key frames without a window; cpu/full_frame.cpp): pre-processing,
// then, when its list fits options.list_budget (kBytesPerListEntry an entry), keys, the single
// sort, tile ranges and rasterization (`stages` exact: task splitting as options.speculation
// says, and rasterize_slices with `early_termination`; vanilla: a tile whole). Over the budget
// it is drawn in passes of tiles (renderer/render_passes.h draw_in_passes, the driver the CUDA
// core runs too), each pass sorting with the whole frame's key and splitting with its slice
// length, into `out`: the image is the single pass's. Throws RenderBudgetError as
// draw_in_passes does. Sets stats' counts (visible, render_list_length: every pass's entries,
// passes, longest_pass, slices: the last pass's) and stage times (summed over the passes, total
// included); leaves the other fields. The buffers hold the last pass's state.
// Occlusion culling (forward_model/occlusion.h; exact frames): `occlusion` is the last frame's
// map reprojected onto this frame, read by pre-processing; `tile_depth`, when given, receives this
// frame's per tile (resized to the grid's tiles; +inf everywhere without early termination) and
// `pixel_depth` its map per pixel (the depth at each pixel's own opaque point; [pixels]), which
// the next frame reprojects.
struct FrameBuffers {
  ProjectedGaussians& projected;
  RenderList& list;
  TileRanges& ranges;
  std::vector<TileSlice>& slices;
  fm::OcclusionMap occlusion{};
  std::vector<float>* tile_depth = nullptr;
  std::vector<float>* pixel_depth = nullptr;
  // Measurement (issue 72): when given, the entries and Gaussians that change a pixel
  // (blend_tile's `changed`) are counted into FrameStats; the frame is then drawn without task
  // splitting, so every tile's transmittance is the composed one.
  std::vector<std::uint8_t>* changed = nullptr;
  // exact frames: when given, the frame's depth grid (options.depth_grid_cell > 0; depth_grid).
  DepthGrid* depth = nullptr;
};
void render_full_frame(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks, const Camera& camera,
                       Pipeline stages, const RenderOptions& options, bool early_termination,
                       const FrameBuffers& buffers, Image& out, FrameStats& stats);

// Renderer::reserve_buffers and buffer_shape of both CPU renderers, over their buffers.
void reserve_frame_buffers(std::size_t gaussians, const BufferShape& shape, ProjectedGaussians& projected,
                           RenderList& list);
BufferShape frame_buffer_shape(const ProjectedGaussians& projected, const RenderList& list);

// The CPU Renderer: the five stages, buffers reused across frames.
class CpuRenderer final : public Renderer {
 public:
  // Throws std::invalid_argument for a null model.
  CpuRenderer(std::shared_ptr<const GaussianModel> model, const RenderOptions& options);
  std::string name() const override { return "cpu"; }
  void render(const Camera& camera, Image& out) override;
  const FrameStats& last_stats() const override { return stats_; }
  const DepthGrid& last_depth_grid() const override { return depth_grid_; }
  const RenderOptions& options() const override { return options_; }
  void set_options(const RenderOptions& options) override;
  // The pre-processed Gaussians (the whole scene: shape.gaussians is not used) and the render
  // list of shape.list_entries, through the host slot (cpu/host_buffer.h). A frame that throws
  // (OutOfMemoryError among others) leaves no occlusion map: the next frame draws unculled.
  void reserve_buffers(int width, int height, const BufferShape& shape) override;
  BufferShape buffer_shape() const override;

  // The intermediate state of the last frame (tests and tools).
  const ProjectedGaussians& projected() const { return projected_; }
  const RenderList& render_list() const { return list_; }
  const TileRanges& tile_ranges() const { return ranges_; }

  // Measure each frame's entries and Gaussians that change a pixel into FrameStats (issue 72;
  // slow, for benchmarks: such frames are drawn without task splitting). Off by default.
  void count_changes(bool on) { count_changes_ = on; }

 private:
  std::shared_ptr<const GaussianModel> model_;
  std::vector<fm::ChunkBounds> chunks_;  // of model_, for chunk culling
  RenderOptions options_;
  ProjectedGaussians projected_;
  RenderList list_;
  TileRanges ranges_;
  std::vector<TileSlice> slices_;  // exact: the split plan
  bool count_changes_ = false;
  std::vector<std::uint8_t> changed_;  // count_changes: per list entry, it changed a pixel
  // Occlusion culling (RenderOptions::occlusion_culling): the last frame's map and where it was
  // drawn (valid: a frame drew it with the current options), and the next frame's.
  // Per pixel (the last frame's, this frame's), and the reprojection's pixels and cells.
  std::vector<float> occlusion_depth_, occlusion_next_, occlusion_now_, occlusion_cells_;
  std::vector<float> occlusion_tiles_;  // this frame's per tile (FrameStats::entries_behind_opaque)
  fm::View occlusion_view_{};
  bool occlusion_valid_ = false;
  DepthGrid depth_grid_;  // the last frame's (RenderOptions::depth_grid_cell)
  FrameStats stats_;
};

// The catgs pipeline on the CPU: speculative key frames, sub-frames from the frustum and sort
// caches, task splitting (cpu/speculative_renderer.cpp). Feeds its own motion predictor with
// the render_at() times; render() advances a clock of 1 / F_target per call.
class SpeculativeRenderer final : public Renderer {
 public:
  SpeculativeRenderer(std::shared_ptr<const GaussianModel> model, const RenderOptions& options);
  std::string name() const override { return "cpu"; }
  void render(const Camera& camera, Image& out) override;
  void render_at(const Camera& camera, double time_s, Image& out) override;
  const FrameStats& last_stats() const override { return stats_; }
  const RenderOptions& options() const override { return options_; }
  void set_options(const RenderOptions& options) override;
  void reserve_buffers(int width, int height, const BufferShape& shape) override;
  BufferShape buffer_shape() const override;

 private:
  // render_at() once the camera is valid; a frame that throws leaves its group to be closed.
  void draw_at(const Camera& camera, double time_s, Image& out);
  // Plans and pre-processes a key frame, its window narrowed while its list is over the budget
  // (SpeculationPlanner::narrower_window); a frame left without a window is drawn into `out` here
  // (render_full_frame) and returns true, one with a window builds the group's caches.
  bool key_frame(const Camera& camera, Image& out);

  std::shared_ptr<const GaussianModel> model_;
  std::vector<fm::ChunkBounds> chunks_;  // of model_, for chunk culling
  RenderOptions options_;
  SpeculationPlanner planner_;
  ProjectedGaussians projected_;
  RenderList list_;
  TileRanges ranges_;
  std::vector<TileSlice> slices_;
  std::vector<uint32_t> cached_;  // frustum cache: Gaussians with list entries
  fm::LodCut key_cut_;            // the LOD cut of the group's key frame (lod.h)
  std::size_t key_visible_ = 0;   // the last key frame's Gaussians with list entries
  FrameStats stats_;
};

}  // namespace catgs::cpu
