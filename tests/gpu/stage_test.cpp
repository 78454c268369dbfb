// stages: each CUDA stage run alone, on a real scene's inputs, against the CPU reference's same
// stage element by element (issue 93; as gsplat tests each op). A failure names the stage and the
// element: "key emission: entry 1203 key 0x... CPU 0x...".
//  preprocess  stage 1 (cuda/preprocess.h) on the uploaded scene: the chunks it keeps against the
//              CPU reference's decision for each chunk (the LOD cut, fm::lod_cut; the view,
//              fm::chunk_outside_view; the occlusion test, fm::chunk_hidden), then each kept
//              Gaussian's tile count (equal, or one apart for a Gaussian on a tile's edge, at most
//              kEdgeTileShare of them) and its mean, conic, opacity, depth and colour (within the
//              tolerances below) against cpu::preprocess on the host model. With an
//              occlusion map, the per-entry test (fm::entry_hidden) shows in the tile counts.
//  emission    stage 2 (cuda/key_emission.h) on the GPU's stage-1 outputs, against cpu::emit_keys
//              on the same outputs read back: every key and value bit for bit.
//  sort        stage 3 (cuda/sort.h) on the CPU's emitted list: the plain 64-bit key and the
//              single sort's 32-bit key (fm::single_sort_packing), against cpu::sort_render_list.
//  ranges      stage 4 (cuda/tile_ranges.h) on the CPU's sorted list, against
//              cpu::identify_tile_ranges, every tile.
//  rasterize   stage 5 (cuda/rasterize.h) on the GPU's stage-1 outputs and the CPU's sorted list
//              and ranges, against cpu::rasterize on the same: every pixel within kPixelTolerance.
// Scenes: the biker (no LOD) and 13 tumblewood copies with their level of detail at 4 px, with
// and without an occlusion map, at the tests' size on real camera paths.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include "cuda/renderer_state.h"
#include "gpu_test_support.h"
#include "scene/gaussian_model.h"

namespace catgs::gputest {
namespace {

namespace st = catgs::cuda::stages;

// Tolerances of stage 1's floats, CUDA against the CPU: the same formulas in another order of
// operations (fused multiply-adds, the device's division and exp). Each stage-1 field of each
// listed Gaussian must be within them; a fault (a wrong sign, a missing low-pass, a wrong SH band)
// is off by far more.
constexpr float kMeanTolerancePx = 1e-2f;   // the 2D mean, pixels
constexpr float kConicTolerance = 1e-2f;    // the conic, relative to its larger diagonal entry
constexpr float kOpacityTolerance = 1e-3f;  // relative
constexpr float kDepthTolerance = 1e-4f;    // relative (at least 1 unit)
constexpr float kColourTolerance = 1e-2f;   // SH colour, absolute (colours ~0..1)
// A Gaussian whose ellipse ends on a tile's edge may reach it on one core and not the other (its
// conic's rounding): its tile count may differ by one, for at most this share of the listed ones.
constexpr double kEdgeTileShare = 1e-4;
constexpr float kPixelTolerance = 2e-3f;  // stage 5: each channel of each pixel (absolute)

// A device buffer of `n` T, zeroed; filled from or read back to the host.
template <class T>
class DeviceArray {
 public:
  explicit DeviceArray(std::size_t n) : n_(n) {
    CATGS_CUDA(cudaMalloc(&ptr_, std::max<std::size_t>(n, 1) * sizeof(T)));
    CATGS_CUDA(cudaMemset(ptr_, 0, std::max<std::size_t>(n, 1) * sizeof(T)));
  }
  explicit DeviceArray(const std::vector<T>& host) : DeviceArray(host.size()) {
    CATGS_CUDA(cudaMemcpy(ptr_, host.data(), host.size() * sizeof(T), cudaMemcpyHostToDevice));
  }
  DeviceArray(const DeviceArray&) = delete;
  DeviceArray& operator=(const DeviceArray&) = delete;
  ~DeviceArray() { cudaFree(ptr_); }
  T* get() const { return ptr_; }
  std::vector<T> read(std::size_t count) const {
    std::vector<T> out(count);
    CATGS_CUDA(cudaDeviceSynchronize());
    if (count) CATGS_CUDA(cudaMemcpy(out.data(), ptr_, count * sizeof(T), cudaMemcpyDeviceToHost));
    return out;
  }
  std::vector<T> read() const { return read(n_); }

 private:
  T* ptr_ = nullptr;
  std::size_t n_;
};

std::string hex(std::uint64_t v) {
  char s[24];
  std::snprintf(s, sizeof(s), "0x%llx", static_cast<unsigned long long>(v));
  return s;
}

// Stage 1's buffers on the device with room for every chunk of the scene (the renderer sizes
// them by the view; the stage's answers do not depend on it).
struct Stage1 {
  std::uint64_t chunks, slots;
  DeviceArray<st::Splat> splat;
  DeviceArray<float4> color;
  DeviceArray<float> depth;
  DeviceArray<ushort4> rect;
  DeviceArray<std::uint32_t> tiles_touched, tile_mask, chunk_total;
  DeviceArray<std::uint32_t> live_index, live_keep, live_slot;
  DeviceArray<unsigned> live_count;
  DeviceArray<unsigned char> live_temp;
  DeviceArray<std::uint32_t> big_index, big_parts;
  DeviceArray<unsigned> big_count;
  DeviceArray<unsigned long long> visible, depth_range;

  explicit Stage1(std::uint64_t n)
      : chunks(fm::chunk_count(n)),
        slots(chunks * fm::kChunkSize),
        splat(slots),
        color(slots),
        depth(slots),
        rect(slots),
        tiles_touched(slots),
        tile_mask(slots),
        chunk_total(chunks),
        live_index(chunks),
        live_keep(chunks),
        live_slot(chunks),
        live_count(1),
        live_temp(st::live_scan_temp_bytes(chunks)),
        big_index(slots),
        big_parts(static_cast<std::size_t>(catgs::cuda::tune::kHugeListed) * catgs::cuda::tune::kHugeParts),
        big_count(2),
        visible(1),
        depth_range(2) {}
  st::Projected projected() const {
    return {splat.get(), color.get(), depth.get(), rect.get(), tiles_touched.get(), tile_mask.get(), chunk_total.get()};
  }
  st::LiveChunks live() const {
    return {live_index.get(),
            live_count.get(),
            live_keep.get(),
            live_slot.get(),
            chunks,
            live_temp.get(),
            st::live_scan_temp_bytes(chunks)};
  }
  st::BigList big() const { return {big_index.get(), big_count.get(), slots, big_parts.get()}; }
};

// What stage 1 left, read back: the kept chunks and, per slot, a ProjectedGaussians in slot space
// (entry s: slot s, Gaussian kept[s / kChunkSize] * kChunkSize + s % kChunkSize), the input of
// the CPU's later stages.
struct Stage1Result {
  std::vector<std::uint32_t> kept;  // scene chunks, in slot order
  catgs::cpu::ProjectedGaussians slots;
};

Stage1Result read_stage1(const Stage1& s, const fm::OcclusionMap& host_map) {
  Stage1Result r;
  const unsigned count = s.live_count.read(1)[0];
  r.kept = s.live_index.read(count);
  const std::size_t n = static_cast<std::size_t>(count) * fm::kChunkSize;
  const std::vector<st::Splat> splat = s.splat.read(n);
  const std::vector<float4> color = s.color.read(n);
  const std::vector<float> depth = s.depth.read(n);
  const std::vector<ushort4> rect = s.rect.read(n);
  const std::vector<std::uint32_t> touched = s.tiles_touched.read(n), totals = s.chunk_total.read(count);
  catgs::cpu::ProjectedGaussians& p = r.slots;
  p.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    p.tiles_touched[i] = totals[i / fm::kChunkSize] != 0 ? touched[i] : 0u;  // records.h listed_tiles
    if (p.tiles_touched[i] == 0) continue;
    const st::Splat& sp = splat[i];
    p.mean2d[i] = {sp.mean_ab.x, sp.mean_ab.y};
    p.conic[i] = {sp.mean_ab.z, sp.mean_ab.w, sp.c_opacity_q_log2.x};
    p.opacity[i] = sp.c_opacity_q_log2.y;
    p.q_max[i] = sp.c_opacity_q_log2.z;
    p.depth[i] = depth[i];
    p.color[i] = {color[i].x, color[i].y, color[i].z};
    p.tile_rect[i] = {rect[i].x, rect[i].y, rect[i].z, rect[i].w};
  }
  p.occlusion = host_map;  // the CPU's emission applies the per-entry test as stage 1 did
  p.chunks_kept = count;
  return r;
}

// One case: a scene, a view, its LOD bound and an occlusion map (host cells, fm::occlusion_cells'
// layout; empty: none).
struct StageCase {
  std::string scene, view;
  const GaussianModel* model;
  const catgs::cuda::DeviceScene* dev;
  Camera camera;
  float lod_error_px;
  std::vector<float> map_cells;
};

// Stage 1 against the CPU: the kept chunks, then each Gaussian of them. Adds the rows; returns the
// GPU's outputs for the later stages.
Stage1Result check_preprocess(const StageCase& c, Stage1& s) {
  const Camera& cam = c.camera;
  const fm::OcclusionMap host_map =
      c.map_cells.empty() ? fm::OcclusionMap{} : fm::occlusion_cells(c.map_cells.data(), cam.width, cam.height);
  DeviceArray<float> map_dev(c.map_cells);
  const fm::OcclusionMap dev_map =
      c.map_cells.empty() ? fm::OcclusionMap{} : fm::occlusion_cells(map_dev.get(), cam.width, cam.height);
  st::preprocess(catgs::cuda::scene_view(*c.dev, c.lod_error_px), catgs::cuda::camera_params(cam), true, fm::kAllTiles,
                 s.projected(), s.live(), s.visible.get(), s.depth_range.get(), s.big(), nullptr, dev_map);
  Stage1Result r = read_stage1(s, host_map);

  // The chunk cull: the LOD cut, the view and the occlusion test, chunk by chunk.
  const std::vector<fm::ChunkBounds> bounds = catgs::chunk_bounds_of(*c.model);
  const fm::View view = fm::view_of(cam);
  const fm::LodCut cut = fm::lod_cut(c.model->lod, view, c.lod_error_px);
  std::vector<std::uint32_t> want;
  long long by_lod = 0, by_view = 0, by_map = 0;
  for (std::uint32_t k = 0; k < bounds.size(); ++k) {
    if (!cut.drawn(k)) {
      ++by_lod;
      continue;
    }
    if (fm::chunk_outside_view(bounds[k], view)) {
      ++by_view;
      continue;
    }
    if (fm::chunk_hidden(host_map, bounds[k], view)) {
      ++by_map;
      continue;
    }
    want.push_back(k);
  }
  std::string first;
  for (std::size_t i = 0; i < std::max(want.size(), r.kept.size()) && first.empty(); ++i)
    if (i >= want.size() || i >= r.kept.size() || want[i] != r.kept[i])
      first = "chunk cull: kept chunk " + std::to_string(i) + " is " +
              (i < r.kept.size() ? std::to_string(r.kept[i]) : "none") + " on CUDA, " +
              (i < want.size() ? std::to_string(want[i]) : "none") + " by the CPU's cut and tests";
  add({"stages", c.scene, c.view, "chunk cull", 0, 0, 0, static_cast<long long>(want.size()),
       static_cast<long long>(r.kept.size()), first.empty(),
       first.empty() ? "kept " + std::to_string(want.size()) + " of " + std::to_string(bounds.size()) + " (LOD cut " +
                           std::to_string(by_lod) + ", view " + std::to_string(by_view) + ", occlusion map " +
                           std::to_string(by_map) + ")"
                     : first});

  // Each Gaussian of the kept chunks against cpu::preprocess on the host model.
  catgs::cpu::ProjectedGaussians cpu;
  catgs::cpu::preprocess(*c.model, bounds, cam, Pipeline::exact, cpu, fm::kAllTiles, c.lod_error_px, host_map);
  first.clear();
  long long listed = 0, entries = 0, edge = 0;
  float worst[5] = {};  // mean, conic, opacity, depth, colour
  const float tolerance[5] = {kMeanTolerancePx, kConicTolerance, kOpacityTolerance, kDepthTolerance, kColourTolerance};
  const char* field[5] = {"mean", "conic", "opacity", "depth", "colour"};
  const catgs::cpu::ProjectedGaussians& p = r.slots;
  for (std::size_t s_i = 0; s_i < p.tiles_touched.size(); ++s_i) {
    const std::size_t g =
        static_cast<std::size_t>(r.kept[s_i / fm::kChunkSize]) * fm::kChunkSize + s_i % fm::kChunkSize;
    if (g >= c.model->size()) continue;
    const std::uint32_t a = p.tiles_touched[s_i], b = cpu.tiles_touched[g];
    std::ostringstream why;
    if (a != b && (a == 0 || b == 0 || std::max(a, b) - std::min(a, b) > 1)) {
      why << "tiles_touched " << a << ", CPU " << b;
    } else if (a != 0) {
      edge += a != b;
      ++listed;
      entries += a;
      const glm::vec3 dk = p.conic[s_i] - cpu.conic[g];
      const float err[5] = {
          glm::length(p.mean2d[s_i] - cpu.mean2d[g]),
          std::max({std::fabs(dk.x), std::fabs(dk.y), std::fabs(dk.z)}) /
              std::max(std::fabs(cpu.conic[g].x), std::fabs(cpu.conic[g].z)),
          std::fabs(p.opacity[s_i] - cpu.opacity[g]) / cpu.opacity[g],
          std::fabs(p.depth[s_i] - cpu.depth[g]) / std::max(1.0f, std::fabs(cpu.depth[g])),
          std::max({std::fabs(p.color[s_i].x - cpu.color[g].x), std::fabs(p.color[s_i].y - cpu.color[g].y),
                    std::fabs(p.color[s_i].z - cpu.color[g].z)})};
      int off = -1;  // the first field out of its tolerance
      for (int k = 0; k < 5; ++k) {
        worst[k] = std::max(worst[k], err[k]);
        if (off < 0 && !(err[k] <= tolerance[k])) off = k;
      }
      if (off >= 0) why << field[off] << " off by " << err[off];
      if (off == 1)
        why << ": (" << p.conic[s_i].x << ", " << p.conic[s_i].y << ", " << p.conic[s_i].z << "), CPU ("
            << cpu.conic[g].x << ", " << cpu.conic[g].y << ", " << cpu.conic[g].z << ")";
    }
    if (!why.str().empty() && first.empty()) first = "preprocess: Gaussian " + std::to_string(g) + ": " + why.str();
  }
  if (first.empty() && static_cast<double>(edge) > kEdgeTileShare * static_cast<double>(listed))
    first = "preprocess: " + std::to_string(edge) + " of " + std::to_string(listed) +
            " Gaussians' tile counts differ by one (at most " + std::to_string(kEdgeTileShare) + " may)";
  char note[240];
  std::snprintf(note, sizeof(note),
                "%s layout, %lld listed, %lld a tile apart; worst: mean %.2g px, conic %.2g, opacity %.2g, depth %.2g "
                "(relative), colour %.2g",
                c.dev->compact() ? "compact" : "float", listed, edge, worst[0], worst[1], worst[2], worst[3], worst[4]);
  add({"stages", c.scene, c.view, "preprocess", 0, worst[0], 0, static_cast<long long>(catgs::cpu::count_entries(cpu)),
       entries, first.empty() && listed > 0, first.empty() ? note : first + " (" + note + ")"});
  return r;
}

// Stage 2 on the GPU's stage-1 outputs against cpu::emit_keys on the same, read back.
catgs::cpu::RenderList check_emission(const StageCase& c, const Stage1& s, const Stage1Result& r) {
  const Camera& cam = c.camera;
  const catgs::cpu::TileGrid grid = catgs::cpu::TileGrid::of(cam.width, cam.height);
  catgs::cpu::RenderList cpu;
  catgs::cpu::emit_keys(r.slots, grid, Pipeline::exact, catgs::RenderListBudget{}, cpu);
  const std::uint64_t n = r.slots.tiles_touched.size(), chunks = r.kept.size();
  const st::LiveChunks live = s.live();
  DeviceArray<std::uint64_t> chunk_start(std::max<std::uint64_t>(chunks, 1)), ends(n);
  DeviceArray<unsigned char> temp(st::scan_temp_bytes(chunks));
  const st::Projected projected = s.projected();
  st::scan_chunks(projected, n, chunk_start.get(), temp.get(), st::scan_temp_bytes(chunks), nullptr);
  st::gaussian_ends(projected, n, live.walk(), chunk_start.get(), ends.get(), nullptr);
  const std::size_t L = cpu.keys.size();
  DeviceArray<std::uint64_t> keys(L);
  DeviceArray<std::uint32_t> values(L);
  const st::TileTests tests{st::TileTestKind::ellipse, s.splat.get(), {}, cam.width, cam.height};
  st::emit_keys(projected, ends.get(), n, live.walk(), catgs::cuda::camera_params(cam), tests, s.big(), keys.get(),
                nullptr, fm::plain_key_packing(), values.get(), nullptr, 0, nullptr);
  const std::vector<std::uint64_t> k = keys.read();
  const std::vector<std::uint32_t> v = values.read();
  std::string first;
  for (std::size_t i = 0; i < L && first.empty(); ++i)
    if (k[i] != cpu.keys[i] || v[i] != cpu.values[i])
      first = "key emission: entry " + std::to_string(i) + " key " + hex(k[i]) + " value " + std::to_string(v[i]) +
              ", CPU " + hex(cpu.keys[i]) + " value " + std::to_string(cpu.values[i]);
  add({"stages", c.scene, c.view, "key emission", 0, 0, 0, static_cast<long long>(L), static_cast<long long>(L),
       first.empty() && L > 0, first.empty() ? "every key and value equal" : first});
  return cpu;
}

// Stage 4's answer against the CPU's, tile by tile.
void check_ranges(const StageCase& c, const std::string& name, const std::vector<uint2>& got,
                  const catgs::cpu::TileRanges& want) {
  std::string first;
  for (std::size_t t = 0; t < want.size() && first.empty(); ++t)
    if (got[t].x != want[t].x || got[t].y != want[t].y)
      first = name + ": tile " + std::to_string(t) + " [" + std::to_string(got[t].x) + ", " + std::to_string(got[t].y) +
              "), CPU [" + std::to_string(want[t].x) + ", " + std::to_string(want[t].y) + ")";
  const auto tiles = static_cast<long long>(want.size());
  add({"stages", c.scene, c.view, name, 0, 0, 0, tiles, tiles, first.empty(),
       first.empty() ? "every tile equal" : first});
}

// Stages 3 and 4 on the CPU's emitted list, with the plain key and with the single sort's.
void check_sort_and_ranges(const StageCase& c, const catgs::cpu::RenderList& emitted,
                           catgs::cpu::RenderList& sorted_plain, catgs::cpu::TileRanges& cpu_ranges) {
  const catgs::cpu::TileGrid grid = catgs::cpu::TileGrid::of(c.camera.width, c.camera.height);
  const auto tiles = static_cast<std::uint32_t>(grid.tile_count());
  const std::size_t L = emitted.keys.size();
  const fm::DepthKeyPacking single = catgs::cpu::single_sort_packing_of(emitted, grid);
  for (const fm::DepthKeyPacking packing : {fm::plain_key_packing(), single}) {
    const bool narrow = fm::is_narrow(packing);
    const std::string name = narrow ? "sort (32-bit key)" : "sort (64-bit key)";
    catgs::cpu::RenderList cpu = emitted;
    catgs::cpu::sort_render_list(cpu, packing);
    const int bits = fm::tile_key_bits(tiles) + packing.bits;
    DeviceArray<std::uint32_t> v0(emitted.values), v1(L);
    std::uint32_t* values[2] = {v0.get(), v1.get()};
    std::vector<std::uint64_t> got_keys(L);
    std::vector<std::uint32_t> got_values;
    if (narrow) {
      std::vector<std::uint32_t> k32(L);
      for (std::size_t i = 0; i < L; ++i)
        k32[i] = packing.key32(static_cast<std::uint32_t>(emitted.keys[i] >> 32),
                               static_cast<std::uint32_t>(emitted.keys[i]));
      DeviceArray<std::uint32_t> k0(k32), k1(L);
      std::uint32_t* keys[2] = {k0.get(), k1.get()};
      DeviceArray<unsigned char> temp(st::sort_narrow_temp_bytes(L, bits));
      const int half =
          st::sort_pairs_narrow(keys, values, L, bits, temp.get(), st::sort_narrow_temp_bytes(L, bits), nullptr);
      const std::vector<std::uint32_t> k = (half ? k1 : k0).read();
      std::copy(k.begin(), k.end(), got_keys.begin());
      got_values = (half ? v1 : v0).read();
      // Stage 4 on the 32-bit keys.
      DeviceArray<uint2> ranges(tiles);
      st::tile_ranges(keys[half], packing, L, tiles, ranges.get(), nullptr);
      catgs::cpu::TileRanges want;
      catgs::cpu::identify_tile_ranges(cpu, grid, want);
      check_ranges(c, "tile ranges (32-bit key)", ranges.read(), want);
    } else {
      DeviceArray<std::uint64_t> k0(emitted.keys), k1(L);
      std::uint64_t* keys[2] = {k0.get(), k1.get()};
      DeviceArray<unsigned char> temp(st::sort_temp_bytes(L, bits));
      const int half = st::sort_pairs(keys, values, L, bits, temp.get(), st::sort_temp_bytes(L, bits), nullptr);
      got_keys = (half ? k1 : k0).read();
      got_values = (half ? v1 : v0).read();
      DeviceArray<uint2> ranges(tiles);
      st::tile_ranges(keys[half], packing, L, tiles, ranges.get(), nullptr);
      catgs::cpu::identify_tile_ranges(cpu, grid, cpu_ranges);
      check_ranges(c, "tile ranges (64-bit key)", ranges.read(), cpu_ranges);
      sorted_plain = cpu;
    }
    std::string first;
    for (std::size_t i = 0; i < L && first.empty(); ++i)
      if (got_keys[i] != cpu.keys[i] || got_values[i] != cpu.values[i])
        first = name + ": entry " + std::to_string(i) + " key " + hex(got_keys[i]) + " value " +
                std::to_string(got_values[i]) + ", CPU " + hex(cpu.keys[i]) + " value " + std::to_string(cpu.values[i]);
    add({"stages", c.scene, c.view, name, 0, 0, 0, static_cast<long long>(L), static_cast<long long>(L),
         first.empty() && L > 0, first.empty() ? "every key and value equal" : first});
  }
}

// Stage 5 on the GPU's stage-1 outputs with the CPU's sorted list and ranges.
void check_rasterize(const StageCase& c, const Stage1& s, const Stage1Result& r, const catgs::cpu::RenderList& sorted,
                     const catgs::cpu::TileRanges& ranges) {
  const Camera& cam = c.camera;
  const catgs::cpu::TileGrid grid = catgs::cpu::TileGrid::of(cam.width, cam.height);
  const auto tiles = static_cast<std::uint32_t>(grid.tile_count());
  const glm::vec3 background(0.0f);
  Image want;
  catgs::cpu::rasterize(r.slots, sorted, ranges, grid, background, want);
  std::vector<uint2> host_ranges(tiles);
  for (std::uint32_t t = 0; t < tiles; ++t) host_ranges[t] = {ranges[t].x, ranges[t].y};
  std::vector<std::uint32_t> order(tiles);
  for (std::uint32_t t = 0; t < tiles; ++t) order[t] = t;
  DeviceArray<uint2> d_ranges(host_ranges);
  DeviceArray<std::uint32_t> d_order(order), d_values(sorted.values);
  const std::size_t pixels = static_cast<std::size_t>(cam.width) * cam.height;
  DeviceArray<float> rgb(pixels * 3);
  DeviceArray<std::uint32_t> rgba8(pixels);
  st::rasterize(d_ranges.get(), d_order.get(), 0, tiles, d_values.get(), s.projected(), catgs::cuda::camera_params(cam),
                make_float3(background.x, background.y, background.z), rgb.get(), rgba8.get(), nullptr);
  const std::vector<float> got = rgb.read();
  float worst = 0;
  std::size_t at = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const float d = std::fabs(got[i] - want.rgb[i]);
    if (!(d <= worst)) worst = d, at = i;
  }
  Image gpu = want;
  gpu.rgb = got;
  const Diff d = compare(gpu, want);
  const std::size_t px = at / 3;
  char note[200];
  std::snprintf(note, sizeof(note), "%s pixel (%zu, %zu) channel %zu: %.6f, CPU %.6f",
                worst <= kPixelTolerance ? "worst" : "rasterize:", px % static_cast<std::size_t>(cam.width),
                px / static_cast<std::size_t>(cam.width), at % 3, got.empty() ? 0.0 : got[at],
                want.rgb.empty() ? 0.0 : want.rgb[at]);
  add({"stages", c.scene, c.view, "rasterize", d.psnr, worst, d.max_abs8, static_cast<long long>(sorted.keys.size()),
       static_cast<long long>(sorted.keys.size()), worst <= kPixelTolerance, note});
}

void run_stages(const StageCase& c) {
  Stage1 s(c.model->size());
  const Stage1Result r = check_preprocess(c, s);
  const catgs::cpu::RenderList emitted = check_emission(c, s, r);
  catgs::cpu::RenderList sorted;
  catgs::cpu::TileRanges ranges;
  check_sort_and_ranges(c, emitted, sorted, ranges);
  check_rasterize(c, s, r, sorted, ranges);
}

// A map that hides what lies behind the nearer third of the listed Gaussians' depths over the
// middle of the view (a wall there): enough chunks and entries hidden to test both tests.
std::vector<float> wall_map(const GaussianModel& model, const Camera& cam, float lod_error_px) {
  catgs::cpu::ProjectedGaussians p;
  catgs::cpu::preprocess(model, catgs::chunk_bounds_of(model), cam, Pipeline::exact, p, fm::kAllTiles, lod_error_px);
  std::vector<float> depths;
  for (std::size_t i = 0; i < p.tiles_touched.size(); ++i)
    if (p.tiles_touched[i]) depths.push_back(p.depth[i]);
  std::nth_element(depths.begin(), depths.begin() + depths.size() / 3, depths.end());
  const float wall = depths.empty() ? INFINITY : depths[depths.size() / 3];
  std::vector<float> cells(fm::occlusion_cell_count(cam.width, cam.height), INFINITY);
  std::size_t offset = 0;
  for (int k = 0; k < fm::kOcclusionLevels; ++k) {
    const int cx = fm::occlusion_cells_x(cam.width, k), cy = fm::occlusion_cells_y(cam.height, k);
    for (int y = 0; y < cy; ++y)
      for (int x = 0; x < cx; ++x)
        if (x >= cx / 4 && x < cx - cx / 4 && y >= cy / 4 && y < cy - cy / 4)
          cells[offset + static_cast<std::size_t>(y) * cx + x] = wall;
    offset += static_cast<std::size_t>(cx) * cy;
  }
  return cells;
}

class Stages : public GpuTest {};

TEST_F(Stages, BikerEachStageAgainstTheCpu) {
  CATGS_GPU_REQUIRE({"biker"});
  const SharedScene& b = biker();
  const std::vector<Camera> views = orbit_views(*b.model, config().W, config().H);
  for (std::size_t k = 0; k < views.size(); k += 2)
    run_stages({"biker", "orbit" + std::to_string(k), b.model.get(), b.dev.get(), views[k], 0.0f, {}});
}

TEST_F(Stages, CityLodCutAndOcclusionEachStageAgainstTheCpu) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"}, {"mipnerf360_bicycle"});
  const CityWithLod& c = city13_with_lod();
  for (const std::size_t k : {std::size_t{10}, c.trace.size() - 10}) {
    const Camera& cam = c.trace[k].camera;
    const std::string view = "bicycle" + std::to_string(k);
    run_stages({"tumblewood_sh2 x13 lod", view, c.lod.get(), c.dev.get(), cam, 4.0f, {}});
    run_stages(
        {"tumblewood_sh2 x13 lod", view + " +map", c.lod.get(), c.dev.get(), cam, 4.0f, wall_map(*c.lod, cam, 4.0f)});
  }
}

}  // namespace
}  // namespace catgs::gputest
