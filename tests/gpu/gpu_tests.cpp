// GPU tests of the CUDA render core against the CPU reference (run on a GPU machine by
// scripts/gpu_run.sh; no GoogleTest there). Prints a table, writes it with --out, and exits
// non-zero when any check fails.
//
//   catgs-gpu-tests --scenes DIR --traces DIR [--out table.md] [--quick] [--skip-large]
//                   [--only budget|passes|lod|hostile]
//
// DIR holds flowers_sh3.ply, biker.compressed.ply and tumblewood_sh2.compressed.ply (the compact
// copy: the 85 MB original does not fit a GPU run's 64 MiB of files); TRACES holds
// flowers_sh3.cameras.json.
//
// Checks:
//  equal      CUDA == CPU for vanilla and exact, three scenes x 4 views at 1280x720: PSNR >= 50 dB
//             over 8-bit RGB (max abs error of the float image and of the 8-bit image reported),
//             and the render list lengths of both.
//  warpcull   CUDA exact with and without the rasterizer's optional per-warp skip: bit-identical.
//  depthsort  CUDA exact and catgs with the depth-first sort and with the single sort: the same
//             list lengths; exact >= 60 dB (the single sort's 32-bit key quantises the depth,
//             forward_model/key_packing.h); catgs bit-identical (its key frames sort plain keys)
//             with the same decisions.
//  exactsplit CUDA exact with heavy tiles split into slices of the paper's length (min_slice 0)
//             vs CUDA exact with every tile blended whole: PSNR >= 50 dB (renderer.h: the later
//             slices' termination rule), and tiles were really split.
//  exact~van  CUDA exact vs CUDA vanilla: PSNR >= 40 dB and a shorter render list.
//  grow       one renderer across scenes and sizes (small -> large -> small): every frame equals
//             a fresh renderer's frame, and buffers grow without errors.
//  steady     1000 frames in a row (after a warm pass over the same trace): no buffer growth,
//             no allocation, no change in device memory in use.
//  tiles18    8192x4608 (147456 tiles, 18 tile-key bits) CUDA == CPU.
//  list>2^31  a render list of more than 2^31 entries renders (or fails with a clear CudaError
//             for lack of device memory); > 2^32 - 1 entries throws std::length_error.
//  budget     the render-list budget (renderer.h; issue 22): 20 k whole-image Gaussians at 1280x720
//             (72 M entries, over the default 59 M) are refused by CUDA vanilla, exact and catgs
//             with RenderBudgetError naming the same entry count as the CPU core's refusal, before
//             any list buffer grows (buffers held under a tenth of the list's 24 bytes an entry);
//             the same renderer then draws the scene at 64x48 (within the budget) equal to the CPU
//             (>= 50 dB, the same list).
//  passes     the budget's passes and narrowed windows (issue 35), biker at 1280x720: vanilla and
//             exact with a third of their list a pass: >= 3 passes, as many as the CPU's, the
//             list's total the one-pass length, PSNR >= 50 dB vs the CPU's passes and >= 60 dB vs
//             one CUDA pass; catgs over a 40 deg/s orbit, (orbit-fb) a budget of a third of the
//             exact list: every frame an exact frame in passes, >= 60 dB vs the unbudgeted CUDA
//             exact frame; (orbit-nw) a budget halfway between the windowed key lists: some key
//             frames narrowed; both: CPU and CUDA take the same decisions (key frame, W, narrowed,
//             passes) on >= 95% of frames and agree >= 50 dB there. `--only passes` runs these
//             and the budget rows alone.
//  city26M    49 tumblewood copies (26.6 M Gaussians): CUDA == CPU on a fly-over view.
//  chunkcull  13 tumblewood copies: one CUDA exact renderer (single sort, and one depth first)
//             draws a fly-over view, then a view of the centre copies, where most chunks are
//             culled and keep the first frame's tile counts unwritten: CUDA == CPU (>= 50 dB, the
//             same list) on both, and fewer than half the chunks were kept on the second.
//  lod        13 tumblewood copies with their level of detail (scene_tools/lod_build.h), along
//             the fly-over at 120 FPS: CUDA exact == CPU exact on 4 views at the default
//             RenderOptions::lod_error_px and at 4 px (where many merged chunks are drawn; >= 50
//             dB, the same list); CUDA catgs vs CPU catgs at 4 px frame by frame (the same
//             key/sub-frame decisions on >= 95% of frames, >= 50 dB where they agree); CUDA exact
//             at lod_error_px 0 on the LOD scene == CUDA exact on the scene without LOD (bit for
//             bit), and fewer chunks kept at 4 px than without LOD.
//  hostile    issue 49's hostile values (tests/common/hostile_values.h) in every 7th Gaussian of
//             biker and flowers_sh3, straight to the CUDA core: vanilla, exact and catgs over 24
//             orbit frames end in a clear error or a finite image; CUDA exact == CPU exact on the
//             first view (>= 50 dB, the same list). `--only hostile [--quick]` (320x180) runs them
//             alone, under compute-sanitizer memcheck with gpu_run.sh --sanitize.
// catgs pipeline (paper sec. 3; issue 4), over real camera paths interpolated at 120 FPS:
//  catgs=cpu  CUDA catgs vs the CPU reference's catgs, frame by frame: the same key/sub-frame
//             decisions on >= 95% of frames, and where they agree PSNR >= 50 dB.
//  subframes  CUDA catgs vs a full CUDA exact render of the same pose: sub-frames mean PSNR >= 45 dB
//             (identical frames counted as 100 dB) and min >= 35 dB; key frames >= 50 dB; some
//             sub-frames served.
//  split      task splitting on vs off (every frame a key frame): max abs <= 1e-5 per channel with
//             early termination off, PSNR >= 50 dB with it on; and tiles were really split.
//  abrupt     a jump re-keys (the frame after it is a key frame equal to the full render); a stop
//             keeps W = W_initial; a fast turn in place shrinks W by the paper's rule and shows no
//             holes (>= 30 dB against the full render); W = 0 renders every frame in full.
//  steady     catgs: a second pass over the same trace allocates nothing.
// Server frame path (issue 5):
//  yuv420     CudaRenderer::render_yuv420_at (GPU colour conversion) into a pitched host target
//             and into device planes: every Y, Cb, Cr code value equals the CPU reference
//             conversion (rgba_to_yuv420_bt709) of the same frame's RGBA8, for exact and catgs
//             frames, at a size that is not a multiple of the tile size.
#include <cuda_runtime.h>

#include <cmath>
#include <cstring>
#include <random>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "common/image_io.h"
#include "cpu/cpu_renderer.h"
#include "cuda/cuda_renderer.h"
#include "cuda/records.h"
#include "scene/ply_io.h"
#include "scene/scene_bounds.h"
#include "scene_tools/city.h"
#include "scene_tools/lod_build.h"
#include "scene_tools/morton.h"
#include "camera/trace.h"
#include "colour/yuv420.h"
#include "common/cli_args.h"
#include "../common/hostile_values.h"

namespace {

using catgs::Camera;
using catgs::GaussianModel;
using catgs::Image;
using catgs::Pipeline;

struct Row {
  std::string test, scene, view, pipeline;
  double psnr = 0, max_abs = 0;
  int max_abs8 = 0;
  long long list_ref = -1, list_gpu = -1;
  bool pass = false;
  std::string note;
};
std::vector<Row> g_rows;

struct Diff {
  double psnr, max_abs;
  int max_abs8;
};
Diff compare(const Image& a, const Image& b) {
  Diff d{catgs::psnr_rgba8(a, b), 0.0, 0};
  if (a.rgb.size() == b.rgb.size())
    for (std::size_t i = 0; i < a.rgb.size(); ++i)
      d.max_abs = std::max(d.max_abs, static_cast<double>(std::fabs(a.rgb[i] - b.rgb[i])));
  for (std::size_t i = 0; i < a.rgba8.size(); ++i)
    d.max_abs8 = std::max(d.max_abs8, std::abs(static_cast<int>(a.rgba8[i]) - static_cast<int>(b.rgba8[i])));
  return d;
}

std::string fmt_psnr(double p) {
  char b[32];
  if (std::isinf(p)) return "inf";
  std::snprintf(b, sizeof b, "%.2f", p);
  return b;
}

void add(Row r) {
  std::printf("%-10s %-16s %-7s %-8s %8s %10.3g %4d %12lld %12lld  %s %s\n", r.test.c_str(), r.scene.c_str(),
              r.view.c_str(), r.pipeline.c_str(), fmt_psnr(r.psnr).c_str(), r.max_abs, r.max_abs8, r.list_ref,
              r.list_gpu, r.pass ? "PASS" : "FAIL", r.note.c_str());
  std::fflush(stdout);
  g_rows.push_back(std::move(r));
}

std::shared_ptr<GaussianModel> load(const std::string& path, float scale) {
  auto m = std::make_shared<GaussianModel>(catgs::load_scene(path));
  if (scale != 1.0f) catgs::scale_scene(*m, scale);
  return m;
}

// Four orbit views (0, 90, 180, 270 degrees) around the scene's robust bounds, world up -y.
std::vector<Camera> orbit_views(const GaussianModel& m, int w, int h) {
  catgs::GeneratorParams g;
  g.width = w;
  g.height = h;
  g.rate_hz = 1.0;
  g.duration_s = 3.0;
  g.up = {0.0f, -1.0f, 0.0f};
  const auto rb = catgs::robust_bounds(m);
  const glm::vec3 e = rb.extent();
  const float r = 0.6f * std::max(e.x, std::max(e.y, e.z));
  std::vector<Camera> v;
  for (const auto& tc : catgs::make_orbit(rb, r, 0.3f * r, 270.0f, g)) v.push_back(tc.camera);
  return v;
}

// CUDA vs CPU for both pipelines over `views`, plus exact-vs-vanilla on the GPU.
void equality(const std::string& name, std::shared_ptr<GaussianModel> model, const std::vector<Camera>& views,
              std::shared_ptr<const catgs::cuda::DeviceScene> dev) {
  catgs::RenderOptions ov, oe;
  ov.pipeline = Pipeline::vanilla;
  oe.pipeline = Pipeline::exact;
  catgs::cpu::CpuRenderer cpu_v(model, ov), cpu_e(model, oe);
  catgs::cuda::CudaRenderer gpu_v(dev, ov), gpu_e(dev, oe);  // two renderers, one scene
  for (std::size_t k = 0; k < views.size(); ++k) {
    Image cv, ce, gv, ge;
    cpu_v.render(views[k], cv);
    cpu_e.render(views[k], ce);
    gpu_v.render(views[k], gv);
    gpu_e.render(views[k], ge);
    const std::string view = std::to_string(k);
    for (int e = 0; e < 2; ++e) {
      const Image& c = e ? ce : cv;
      const Image& g = e ? ge : gv;
      const auto& cs = e ? cpu_e.last_stats() : cpu_v.last_stats();
      const auto& gs = e ? gpu_e.last_stats() : gpu_v.last_stats();
      const Diff d = compare(c, g);
      add({"equal", name, view, e ? "exact" : "vanilla", d.psnr, d.max_abs, d.max_abs8,
           static_cast<long long>(cs.render_list_length), static_cast<long long>(gs.render_list_length), d.psnr >= 50.0,
           ""});
    }
    {  // the depth-first sort orders by the full depth, the single sort by the 32-bit key's
       // quantised depth (forward_model/key_packing.h): the same entries, and ties of depths
       // within 3e-5 of each other in index order instead of depth order
      catgs::cuda::CudaOptions depth_first_sort;  // gpu_e sorts once (exact's default)
      depth_first_sort.depth_first_sort = true;
      catgs::cuda::CudaRenderer depth_first(dev, oe, depth_first_sort);
      Image gt;
      depth_first.render(views[k], gt);
      const Diff d = compare(ge, gt);
      const auto ls = depth_first.last_stats().render_list_length, le = gpu_e.last_stats().render_list_length;
      add({"depthsort", name, view, "exact", d.psnr, d.max_abs, d.max_abs8, static_cast<long long>(ls),
           static_cast<long long>(le), d.psnr >= 60.0 && ls == le, "depth-first sort vs single (32-bit key) sort"});
    }
    {  // exact splits heavy tiles into slices (renderer.h): pixels whose transmittance drops below
       // 1e-4 inside a later slice keep that slice's Gaussians behind the stop. At the paper's
       // slice length (min_slice 0) most tiles of these views split; at the default floor of 2048
       // few do at 1280x720.
      catgs::RenderOptions whole = oe, fine = oe;
      whole.speculation.task_splitting = false;
      fine.speculation.min_slice_entries = 0;
      catgs::cuda::CudaRenderer unsplit(dev, whole), split(dev, fine);
      Image gw, gs;
      unsplit.render(views[k], gw);
      split.render(views[k], gs);
      const Diff d = compare(gw, gs);
      // The longest slice is shorter than the heaviest tile only where tiles were split.
      const std::size_t longest = split.diagnostics().heaviest_tile_entries;
      const std::size_t heaviest = unsplit.diagnostics().heaviest_tile_entries;
      add({"exactsplit", name, view, "exact", d.psnr, d.max_abs, d.max_abs8,
           static_cast<long long>(unsplit.last_stats().render_list_length),
           static_cast<long long>(split.last_stats().render_list_length), d.psnr >= 50.0 && longest < heaviest,
           "slices of the paper's length vs every tile whole: longest slice " + std::to_string(longest) +
               ", heaviest tile " + std::to_string(heaviest)});
    }
    const Diff d = compare(gv, ge);
    const auto lv = gpu_v.last_stats().render_list_length, le = gpu_e.last_stats().render_list_length;
    char note[64];
    std::snprintf(note, sizeof note, "list x%.2f shorter",
                  static_cast<double>(lv) / std::max<double>(1.0, static_cast<double>(le)));
    add({"exact~van", name, view, "ex/van", d.psnr, d.max_abs, d.max_abs8, static_cast<long long>(lv),
         static_cast<long long>(le), d.psnr >= 40.0 && le < lv, note});
  }
}

// ---- catgs ----

// A real camera path moved onto `m` (tools/scene_tools/city.h) at 120 FPS, at least `frames` frames.
catgs::Trace real_trace(const GaussianModel& m, const std::string& cameras, int w, int h, std::size_t frames) {
  auto keys = catgs::load_inria_cameras(cameras);
  catgs::Trace t = catgs::fit_trace_to_scene(keys, m, {0.0f, -1.0f, 0.0f}, 0.6f, 120.0, 0.5, w, h);
  if (t.size() > frames) t.resize(frames);
  return t;
}

catgs::RenderOptions catgs_options() {
  catgs::RenderOptions o;
  o.pipeline = Pipeline::catgs;
  return o;
}

// catgs=cpu: the CUDA and the CPU catgs take the same decisions and draw the same images.
void catgs_vs_cpu(const std::string& name, const std::string& view, std::shared_ptr<GaussianModel> model,
                  std::shared_ptr<const catgs::cuda::DeviceScene> dev, const catgs::Trace& trace) {
  catgs::cpu::SpeculativeRenderer c(model, catgs_options());
  catgs::cuda::CudaOptions depth_first, no_cull, one_sort;
  depth_first.depth_first_sort = true;  // the default for catgs, set to say what is compared
  no_cull.tile_culling = false;
  one_sort.depth_first_sort = false;
  catgs::cuda::CudaRenderer g(dev, catgs_options(), depth_first), unculled(dev, catgs_options(), no_cull),
      single_sort(dev, catgs_options(), one_sort);
  // A CUDA-only switch that must change neither a decision, a list length nor a bit of the image.
  struct SameFrames {
    std::size_t frame = 0, same_decision = 0, subs = 0, same_lists = 0, differing = 0;
    double max_abs = 0;
    int max8 = 0;
    std::string first;  // where the images first differ, for the note
    void add(const catgs::FrameStats& want, const Image& want_image, const catgs::FrameStats& got,
             const Image& got_image) {
      const std::size_t f = frame++;
      if (got.key_frame != want.key_frame) return;
      ++same_decision;
      subs += want.key_frame ? 0 : 1;
      same_lists += got.render_list_length == want.render_list_length ? 1 : 0;
      const Diff d = compare(want_image, got_image);
      max_abs = std::max(max_abs, d.max_abs);
      max8 = std::max(max8, d.max_abs8);
      if (d.max_abs == 0.0) return;
      ++differing;
      if (!first.empty()) return;
      std::size_t pixels = 0, worst = 0;
      for (std::size_t i = 0; i < want_image.rgb.size(); ++i) {
        if (want_image.rgb[i] == got_image.rgb[i]) continue;
        pixels += 1;
        if (std::fabs(want_image.rgb[i] - got_image.rgb[i]) > std::fabs(want_image.rgb[worst] - got_image.rgb[worst]))
          worst = i;
      }
      const auto p = worst / 3;
      char b[200];
      std::snprintf(b, sizeof b, "; first differs at frame %zu (%s): %zu values, worst at (%zu, %zu) %.6f vs %.6f", f,
                    want.key_frame ? "key" : "sub", pixels, p % static_cast<std::size_t>(want_image.width),
                    p / static_cast<std::size_t>(want_image.width), want_image.rgb[worst], got_image.rgb[worst]);
      first = b;
    }
    bool pass(std::size_t frames) const {
      return same_decision == frames && same_lists == frames && max_abs == 0.0 && subs > 0;
    }
  } cull, sort;
  std::size_t agree = 0, subs = 0, list_equal = 0, keys = 0;
  double min_psnr = INFINITY, max_abs = 0;
  int max8 = 0;
  for (const auto& tc : trace) {
    Image a, b, u, o;
    c.render_at(tc.camera, tc.time_s, a);
    g.render_at(tc.camera, tc.time_s, b);
    unculled.render_at(tc.camera, tc.time_s, u);
    single_sort.render_at(tc.camera, tc.time_s, o);
    const auto& cs = c.last_stats();
    const auto& gs = g.last_stats();
    cull.add(gs, b, unculled.last_stats(), u);
    sort.add(gs, b, single_sort.last_stats(), o);
    if (cs.key_frame != gs.key_frame) continue;
    ++agree;
    subs += gs.key_frame ? 0 : 1;
    if (gs.key_frame) {
      ++keys;
      list_equal += cs.render_list_length == gs.render_list_length ? 1 : 0;
    }
    const Diff d = compare(a, b);
    min_psnr = std::min(min_psnr, d.psnr);
    max_abs = std::max(max_abs, d.max_abs);
    max8 = std::max(max8, d.max_abs8);
  }
  char note[160];
  std::snprintf(note, sizeof note, "%zu frames: decisions agree on %zu (%zu sub-frames), key lists equal %zu/%zu",
                trace.size(), agree, subs, list_equal, keys);
  add({"catgs=cpu", name, view, "catgs", min_psnr, max_abs, max8, -1, -1,
       agree * 100 >= trace.size() * 95 && min_psnr >= 50.0 && subs > 0, note});
  char wide[400];
  std::snprintf(wide, sizeof wide, "tile cull on vs off: %zu/%zu frames decided alike (%zu sub-frames), %zu differ%s",
                cull.same_decision, trace.size(), cull.subs, cull.differing, cull.first.c_str());
  add({"tilecull", name, view, "catgs", cull.max_abs == 0.0 ? INFINITY : 0.0, cull.max_abs, cull.max8, -1, -1,
       cull.pass(trace.size()), wide});
  std::snprintf(
      wide, sizeof wide,
      "depth-first vs single sort: %zu/%zu frames decided alike, %zu same lengths (%zu sub-frames), %zu differ%s",
      sort.same_decision, trace.size(), sort.same_lists, sort.subs, sort.differing, sort.first.c_str());
  add({"depthsort", name, view, "catgs", sort.max_abs == 0.0 ? INFINITY : 0.0, sort.max_abs, sort.max8, -1, -1,
       sort.pass(trace.size()), wide});
}

// subframes: CUDA catgs against the full render of every pose.
void catgs_quality(const std::string& name, const std::string& view,
                   std::shared_ptr<const catgs::cuda::DeviceScene> dev, const catgs::Trace& trace) {
  catgs::RenderOptions oe;
  oe.pipeline = Pipeline::exact;
  catgs::cuda::CudaRenderer g(dev, catgs_options()), full(dev, oe);
  std::vector<double> sub_psnr;
  double key_min = INFINITY, sub_max_abs = 0, window_sum = 0, growth_max = 0;
  int sub_max8 = 0;
  std::size_t keys = 0;
  for (const auto& tc : trace) {
    Image a, b;
    g.render_at(tc.camera, tc.time_s, a);
    full.render(tc.camera, b);
    const auto& gs = g.last_stats();
    const Diff d = compare(a, b);
    if (gs.key_frame) {
      ++keys;
      key_min = std::min(key_min, d.psnr);
      window_sum += gs.window;
      growth_max =
          std::max(growth_max, static_cast<double>(gs.render_list_length) /
                                   std::max<double>(1.0, static_cast<double>(full.last_stats().render_list_length)));
    } else {
      sub_psnr.push_back(std::min(d.psnr, 100.0));
      sub_max_abs = std::max(sub_max_abs, d.max_abs);
      sub_max8 = std::max(sub_max8, d.max_abs8);
    }
  }
  double mean = 0, min = INFINITY;
  for (double v : sub_psnr) {
    mean += v / static_cast<double>(sub_psnr.size());
    min = std::min(min, v);
  }
  char note[200];
  std::snprintf(note, sizeof note,
                "%zu key + %zu sub-frames, mean W %.2f; sub-frames: mean %.2f dB, min %.2f dB; key frames min "
                "%s dB; key list / exact list max %.3f",
                keys, sub_psnr.size(), keys ? window_sum / static_cast<double>(keys) : 0.0, mean, min,
                fmt_psnr(key_min).c_str(), growth_max);
  add({"subframes", name, view, "catgs", mean, sub_max_abs, sub_max8, -1, -1,
       !sub_psnr.empty() && mean >= 45.0 && min >= 35.0 && key_min >= 50.0, note});
}

// split: slices and merge change the image only by float rounding.
void catgs_split(const std::string& name, std::shared_ptr<const catgs::cuda::DeviceScene> dev, const Camera& cam) {
  for (bool et : {false, true}) {
    catgs::RenderOptions on = catgs_options(), off = catgs_options();
    on.speculation.frustum_and_sort_cache = off.speculation.frustum_and_sort_cache = false;
    on.speculation.min_slice_entries = 0;  // the paper's slice length: many slices to merge
    on.speculation.early_termination = off.speculation.early_termination = et;
    off.speculation.task_splitting = false;
    catgs::cuda::CudaRenderer a(dev, on), b(dev, off);
    Image ia, ib;
    a.render(cam, ia);
    b.render(cam, ib);
    const Diff d = compare(ia, ib);
    const std::size_t slices = a.last_stats().slices, tiles = b.last_stats().slices;
    char note[120];
    std::snprintf(note, sizeof note, "early termination %s; %zu slices vs %zu tiles", et ? "on" : "off", slices, tiles);
    add({"split", name, "orbit1", "catgs", d.psnr, d.max_abs, d.max_abs8,
         static_cast<long long>(b.last_stats().render_list_length),
         static_cast<long long>(a.last_stats().render_list_length),
         slices > tiles && (et ? d.psnr >= 50.0 : d.max_abs <= 1e-5), note});
  }
}

// abrupt: a jump, a stop, a fast turn; and W = 0.
void catgs_abrupt(const std::string& name, const GaussianModel& m, std::shared_ptr<const catgs::cuda::DeviceScene> dev,
                  int w, int h) {
  catgs::GeneratorParams gp;
  gp.width = w;
  gp.height = h;
  gp.rate_hz = 120.0;
  gp.duration_s = 1.0;
  gp.up = {0.0f, -1.0f, 0.0f};
  const auto rb = catgs::robust_bounds(m);
  const glm::vec3 e = rb.extent();
  const float r = 0.6f * std::max(e.x, std::max(e.y, e.z));
  const catgs::Trace slow = catgs::make_orbit(rb, r, 0.3f * r, 10.0f, gp);   // 10 deg/s
  const catgs::Trace fast = catgs::make_orbit(rb, r, 0.3f * r, 720.0f, gp);  // 720 deg/s
  catgs::RenderOptions oe;
  oe.pipeline = Pipeline::exact;
  catgs::cuda::CudaRenderer full(dev, oe);
  {  // jump: 40 slow frames, then the pose of the slow orbit's far side, 180 deg away
    catgs::cuda::CudaRenderer g(dev, catgs_options());
    for (int k = 0; k < 40; ++k) g.render_device_at(slow[static_cast<std::size_t>(k)].camera, k / 120.0);
    const Camera jump = fast[30].camera;  // 720 deg/s * 0.25 s: the far side of the orbit
    Image a, b;
    g.render_at(jump, 40 / 120.0, a);
    full.render(jump, b);
    const bool key = g.last_stats().key_frame;
    const Diff d = compare(a, b);
    add({"abrupt", name, "jump", "catgs", d.psnr, d.max_abs, d.max_abs8, -1, -1, key && d.psnr >= 50.0,
         key ? "the frame after the jump is a key frame" : "the frame after the jump was served as a sub-frame"});
  }
  {  // stop: the camera holds still; W = W_initial, sub-frames equal the full render
    catgs::RenderOptions o = catgs_options();
    o.speculation.backoff.frames = 0;  // the paper's rule alone (a poor group before the stop would back off)
    catgs::cuda::CudaRenderer g(dev, o);
    int subs = 0, w_min = 99;
    double min_psnr = INFINITY;
    for (int k = 0; k < 30; ++k) {
      const Camera& cam = slow[std::min<std::size_t>(static_cast<std::size_t>(k), 10)].camera;  // stops at frame 10
      Image a, b;
      g.render_at(cam, k / 120.0, a);
      if (k < 24) continue;  // the predictor's 100 ms window holds only the still poses from here
      full.render(cam, b);
      const auto& s = g.last_stats();
      subs += s.key_frame ? 0 : 1;
      if (s.key_frame) w_min = std::min(w_min, s.window);
      min_psnr = std::min(min_psnr, compare(a, b).psnr);
    }
    add({"abrupt", name, "stop", "catgs", min_psnr, 0, 0, -1, -1, subs > 0 && w_min == 4 && min_psnr >= 45.0,
         "after the stop: " + std::to_string(subs) + "/6 sub-frames, smallest W at a key frame " +
             std::to_string(w_min)});
  }
  {  // fast turn in place: M > 16 px per frame, so W = floor(4 * 16 / M) < 4; images stay close
    gp.duration_s = 0.5;
    const catgs::Trace turn = catgs::make_pan(fast[0].camera.position(), rb.center(), 720.0f, gp);  // 1440 deg/s
    catgs::cuda::CudaRenderer g(dev, catgs_options());
    int w_min = 99, keys = 0;
    double min_psnr = INFINITY;
    for (int k = 0; k < 40; ++k) {
      Image a, b;
      g.render_at(turn[static_cast<std::size_t>(k)].camera, k / 120.0, a);
      full.render(turn[static_cast<std::size_t>(k)].camera, b);
      const auto& s = g.last_stats();
      if (k >= 8 && s.key_frame) {
        w_min = std::min(w_min, s.window);
        ++keys;
      }
      min_psnr = std::min(min_psnr, compare(a, b).psnr);
    }
    // While the scene is in view M is large and W < W_initial; looking at empty space M = 0 and
    // W = W_initial, as the rule says. No frame may show holes (a hole is far below 30 dB); what
    // remains at 4 turns a second is the sort cache's key-frame depth order (biker, 640x360:
    // 33.3 dB at worst, H100 2026-11-21).
    add({"abrupt", name, "turn", "catgs", min_psnr, 0, 0, -1, -1, keys > 0 && w_min < 4 && min_psnr >= 30.0,
         "turning 1440 deg/s: smallest W at a key frame " + std::to_string(w_min) + " over " + std::to_string(keys) +
             " key frames"});
  }
  {  // W = 0: every frame in full
    catgs::RenderOptions o = catgs_options();
    o.speculation.initial_window = 0;
    catgs::cuda::CudaRenderer g(dev, o);
    int keys = 0;
    double min_psnr = INFINITY;
    for (int k = 0; k < 20; ++k) {
      Image a, b;
      g.render_at(slow[static_cast<std::size_t>(k)].camera, k / 120.0, a);
      full.render(slow[static_cast<std::size_t>(k)].camera, b);
      keys += g.last_stats().key_frame ? 1 : 0;
      min_psnr = std::min(min_psnr, compare(a, b).psnr);
    }
    add({"abrupt", name, "W=0", "catgs", min_psnr, 0, 0, -1, -1, keys == 20 && min_psnr >= 50.0,
         std::to_string(keys) + "/20 key frames"});
  }
}

// steady: a catgs trace repeated allocates nothing.
void catgs_steady(const std::string& name, std::shared_ptr<const catgs::cuda::DeviceScene> dev,
                  const catgs::Trace& trace) {
  catgs::cuda::CudaRenderer g(dev, catgs_options());
  auto pass = [&](double t0) {
    for (const auto& tc : trace) g.render_device_at(tc.camera, t0 + tc.time_s);
    (void)g.last_stats();
  };
  pass(0.0);
  const std::size_t a0 = g.diagnostics().allocations, b0 = g.diagnostics().buffer_bytes;
  pass(100.0);
  const std::size_t a1 = g.diagnostics().allocations, b1 = g.diagnostics().buffer_bytes;
  add({"steady", name, std::to_string(trace.size()) + "f", "catgs", 0, 0, 0, -1, -1, a0 == a1 && b0 == b1,
       "allocations " + std::to_string(a0) + " -> " + std::to_string(a1) + ", buffers " + std::to_string(b0 >> 20) +
           " -> " + std::to_string(b1 >> 20) + " MiB"});
}

// A scene of n huge, nearly opaque Gaussians stacked in front of the camera, each covering every
// tile of a 1920x1080 image (vanilla emits n * 8160 entries).
std::shared_ptr<GaussianModel> wall_scene(std::size_t n) {
  auto m = std::make_shared<GaussianModel>();
  m->name = "wall" + std::to_string(n);
  m->sh_degree = 0;
  m->resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    // Depths 5 .. 10: near enough that every Gaussian covers the whole image, and distinct.
    m->means[3 * i + 2] = 5.0f + 1e-5f * static_cast<float>(i);
    for (int a = 0; a < 3; ++a) m->log_scales[3 * i + a] = std::log(40.0f);
    m->rotations[4 * i] = 1.0f;
    m->opacity_logits[i] = 2.0f;  // 0.88: a few layers saturate a pixel
    for (int c = 0; c < 3; ++c)
      m->sh[3 * i + c] = 0.5f * std::sin(0.7f * static_cast<float>(i) + 2.0f * static_cast<float>(c));
  }
  return m;
}

// Code values of `got` that differ from `want` (same size), and the largest difference.
struct PlaneDiff {
  long long mismatched = 0;
  int max_diff = 0;
};
void diff_plane(const std::uint8_t* got, int got_stride, const std::vector<std::uint8_t>& want, int w, int h,
                PlaneDiff& d) {
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      const int e = std::abs(int(got[static_cast<std::size_t>(r) * got_stride + c]) -
                             int(want[static_cast<std::size_t>(r) * w + c]));
      d.mismatched += e != 0;
      d.max_diff = std::max(d.max_diff, e);
    }
}

// render_yuv420_at on the GPU vs the CPU conversion of the same frame, host and device targets.
// `reference` renders the same frames as `converted` (same options, same cameras and times).
void yuv420_check(const std::string& name, const std::string& view, catgs::cuda::CudaRenderer& reference,
                  catgs::cuda::CudaRenderer& converted, const std::vector<Camera>& cams) {
  PlaneDiff host, device;
  int w = cams[0].width, h = cams[0].height;
  const int pad = 64;  // pitched host target: strides past the row
  std::vector<std::uint8_t> y((w + pad) * h), u((w / 2 + pad) * h / 2), v((w / 2 + pad) * h / 2);
  std::uint8_t* dev = nullptr;
  std::size_t pitch = 0;
  if (cudaMallocPitch(reinterpret_cast<void**>(&dev), &pitch, w, h * 2) != cudaSuccess)
    throw std::runtime_error("cudaMallocPitch failed");
  std::vector<std::uint8_t> dev_host(pitch * h * 2);
  double convert_ms = 0;
  for (std::size_t i = 0; i < cams.size(); ++i) {
    const double t = static_cast<double>(i) / 120.0;
    Image img;
    reference.render_at(cams[i], t, img);
    const catgs::Yuv420Image want = catgs::rgba_to_yuv420_bt709(img.rgba8.data(), w, h, w * 4);
    const bool to_device = i % 2 == 1;  // alternate the two targets over the frames
    catgs::Yuv420Target target{w,        h,          catgs::MemoryKind::host, y.data(), w + pad, u.data(), w / 2 + pad,
                               v.data(), w / 2 + pad};
    if (to_device)  // Y rows, then Cb rows, then Cr rows, all at the allocation's pitch
      target = {w,
                h,
                catgs::MemoryKind::device,
                dev,
                int(pitch),
                dev + pitch * h,
                int(pitch),
                dev + pitch * h + pitch * h / 2,
                int(pitch)};
    convert_ms += converted.render_yuv420_at(cams[i], t, target);
    PlaneDiff& d = to_device ? device : host;
    if (to_device) {
      cudaMemcpy(dev_host.data(), dev, dev_host.size(), cudaMemcpyDeviceToHost);
      diff_plane(dev_host.data(), int(pitch), want.y, w, h, d);
      diff_plane(dev_host.data() + pitch * h, int(pitch), want.u, w / 2, h / 2, d);
      diff_plane(dev_host.data() + pitch * h + pitch * h / 2, int(pitch), want.v, w / 2, h / 2, d);
    } else {
      diff_plane(y.data(), w + pad, want.y, w, h, d);
      diff_plane(u.data(), w / 2 + pad, want.u, w / 2, h / 2, d);
      diff_plane(v.data(), w / 2 + pad, want.v, w / 2, h / 2, d);
    }
  }
  cudaFree(dev);
  char note[160];
  std::snprintf(note, sizeof note,
                "%zu frames %dx%d; code values differing: host %lld, device %lld; conversion %.3f ms/frame",
                cams.size(), w, h, host.mismatched, device.mismatched, convert_ms / static_cast<double>(cams.size()));
  add({"yuv420", name, view, catgs::pipeline_name(converted.options().pipeline), 0, 0,
       std::max(host.max_diff, device.max_diff), -1, -1, host.mismatched == 0 && device.mismatched == 0, note});
}

Camera front_camera(int w, int h) { return Camera::from_pose({0.0f, 0.0f, 0.0f}, glm::quat(1, 0, 0, 0), 60.0f, w, h); }

// The scenes every group of checks below uses (flowers and tumblewood only without --quick).
struct Scenes {
  std::string dir, traces;
  bool quick = false;
  int W = 1280, H = 720;
  std::shared_ptr<GaussianModel> biker, flowers, tumble;
  std::shared_ptr<const catgs::cuda::DeviceScene> biker_dev, flowers_dev, tumble_dev;
};

// 1-2: CUDA == CPU and exact ~ vanilla, per scene.
void equality_checks(Scenes& sc) {
  sc.biker = load(sc.dir + "/biker.compressed.ply", 1.0f);
  sc.biker_dev = catgs::cuda::DeviceScene::upload(*sc.biker);
  equality("biker", sc.biker, orbit_views(*sc.biker, sc.W, sc.H), sc.biker_dev);
  if (sc.quick) return;
  sc.flowers = load(sc.dir + "/flowers_sh3.ply", 1.0f);
  sc.flowers_dev = catgs::cuda::DeviceScene::upload(*sc.flowers);
  auto cams = catgs::load_inria_cameras(sc.traces + "/flowers_sh3.cameras.json", sc.W, sc.H);
  std::vector<Camera> views;
  for (int k = 0; k < 4; ++k) views.push_back(cams[cams.size() * static_cast<std::size_t>(k) / 4]);
  equality("flowers_sh3", sc.flowers, views, sc.flowers_dev);
  sc.tumble = load(sc.dir + "/tumblewood_sh2.compressed.ply", 10.0f);
  sc.tumble->name = "tumblewood_sh2";
  sc.tumble_dev = catgs::cuda::DeviceScene::upload(*sc.tumble);
  equality("tumblewood_sh2", sc.tumble, orbit_views(*sc.tumble, sc.W, sc.H), sc.tumble_dev);
}

// 3: one renderer across scenes of different size and images of different size.
void grow_checks(const Scenes& sc) {
  catgs::RenderOptions o;
  catgs::cuda::CudaRenderer r(sc.biker_dev, o);
  struct Step {
    std::shared_ptr<const catgs::cuda::DeviceScene> dev;
    std::shared_ptr<GaussianModel> m;
    int w, h;
  };
  const Step steps[] = {{sc.biker_dev, sc.biker, 640, 360},
                        {sc.tumble_dev, sc.tumble, 1920, 1080},
                        {sc.flowers_dev, sc.flowers, 1280, 720},
                        {sc.biker_dev, sc.biker, 640, 360},
                        {sc.tumble_dev, sc.tumble, 1920, 1080}};
  int k = 0;
  for (const Step& s : steps) {
    Row row{"grow", s.m->name, std::to_string(k++), "exact", 0, 0, 0, -1, -1, false, ""};
    try {
      r.set_scene(s.dev);
      const Camera cam = orbit_views(*s.m, s.w, s.h)[1];
      Image a, b;
      r.render(cam, a);
      catgs::cuda::CudaRenderer fresh(s.dev, o);
      fresh.render(cam, b);
      const Diff d = compare(a, b);
      row.psnr = d.psnr;
      row.max_abs = d.max_abs;
      row.max_abs8 = d.max_abs8;
      row.list_gpu = static_cast<long long>(r.last_stats().render_list_length);
      row.list_ref = static_cast<long long>(fresh.last_stats().render_list_length);
      row.pass = d.max_abs == 0.0 && row.list_gpu == row.list_ref;
      row.note = std::to_string(s.w) + "x" + std::to_string(s.h) + ", buffers " +
                 std::to_string(r.diagnostics().buffer_bytes >> 20) + " MiB, allocations " +
                 std::to_string(r.diagnostics().allocations);
    } catch (const std::exception& e) {
      row.note = e.what();
    }
    add(row);
  }
}

// catgs: CUDA vs CPU, sub-frame quality, split, abrupt motion, steady buffers.
void catgs_checks(const Scenes& sc) {
  const int W = sc.W, H = sc.H;
  const std::size_t frames = sc.quick ? 48 : 240;
  const auto biker_path = real_trace(*sc.biker, sc.traces + "/tandt_train.cameras.json", W, H, frames);
  catgs_vs_cpu("sc.biker", "tandt", sc.biker, sc.biker_dev, biker_path);
  catgs_quality("sc.biker", "tandt", sc.biker_dev, biker_path);
  catgs_split("sc.biker", sc.biker_dev, orbit_views(*sc.biker, W, H)[1]);
  if (!sc.quick) {
    auto flowers_path =
        catgs::interpolate_views(catgs::load_inria_cameras(sc.traces + "/flowers_sh3.cameras.json", W, H), 120.0, 0.5);
    flowers_path.resize(std::min<std::size_t>(flowers_path.size(), 600));
    catgs_vs_cpu("flowers_sh3", "own", sc.flowers, sc.flowers_dev,
                 catgs::Trace(flowers_path.begin(), flowers_path.begin() + 120));
    catgs_quality("flowers_sh3", "own", sc.flowers_dev, flowers_path);
    for (const char* path : {"mipnerf360_bicycle", "tandt_train", "flowers_sh3"}) {
      const auto t = real_trace(*sc.tumble, sc.traces + "/" + path + ".cameras.json", W, H, 600);
      if (std::string(path) == "mipnerf360_bicycle")
        catgs_vs_cpu("tumblewood_sh2", path, sc.tumble, sc.tumble_dev, catgs::Trace(t.begin(), t.begin() + 60));
      catgs_quality("tumblewood_sh2", path, sc.tumble_dev, t);
    }
    catgs_split("tumblewood_sh2", sc.tumble_dev, orbit_views(*sc.tumble, W, H)[1]);
    catgs_abrupt("tumblewood_sh2", *sc.tumble, sc.tumble_dev, W, H);
    catgs_steady("tumblewood_sh2", sc.tumble_dev,
                 real_trace(*sc.tumble, sc.traces + "/tandt_train.cameras.json", W, H, 240));
  } else {
    catgs_abrupt("sc.biker", *sc.biker, sc.biker_dev, W, H);
  }
}

// The server's frame path: GPU colour conversion == CPU reference, exact and catgs frames.
void yuv420_checks(const Scenes& sc) {
  const int w = 1918, h = 1078;  // 1080p-like, not a multiple of 16 or 32
  std::vector<Camera> path;
  for (const auto& tc : real_trace(*sc.biker, sc.traces + "/tandt_train.cameras.json", w, h, sc.quick ? 4 : 24))
    path.push_back(tc.camera);
  for (Pipeline pl : {Pipeline::exact, Pipeline::catgs}) {
    catgs::RenderOptions o;
    o.pipeline = pl;
    catgs::cuda::CudaRenderer reference(sc.biker_dev, o), converted(sc.biker_dev, o);
    yuv420_check("sc.biker", "tandt", reference, converted, path);
  }
}

// 4: 1000 frames in a row without growth of device memory (not under compute-sanitizer, whose
// own allocations move the device's memory in use: --quick skips it).
void steady_checks(const Scenes& sc) {
  const int W = sc.W, H = sc.H;
  auto& m = sc.tumble;
  auto& dev = sc.tumble_dev;
  catgs::GeneratorParams g;
  g.width = W;
  g.height = H;
  g.rate_hz = 120.0;
  g.duration_s = 999.0 / 120.0;
  const auto rb = catgs::robust_bounds(*m);
  const glm::vec3 e = rb.extent();
  const float rad = 0.6f * std::max(e.x, std::max(e.y, e.z));
  const auto trace = catgs::make_orbit(rb, rad, 0.3f * rad, 360.0f, g);
  catgs::RenderOptions o;
  catgs::cuda::CudaRenderer r(dev, o);
  auto pass = [&] {
    for (std::size_t i = 0; i < trace.size(); ++i) {
      o.pipeline = i % 2 ? Pipeline::vanilla : Pipeline::exact;
      r.set_options(o);
      r.render_device(trace[i].camera);
    }
    (void)r.last_stats();
  };
  pass();  // warm: buffers reach the trace's needs
  const std::size_t used0 = catgs::cuda::device_memory_used(), buf0 = r.diagnostics().buffer_bytes,
                    alloc0 = r.diagnostics().allocations;
  pass();
  const std::size_t used1 = catgs::cuda::device_memory_used(), buf1 = r.diagnostics().buffer_bytes,
                    alloc1 = r.diagnostics().allocations;
  Row row{"steady", m->name, "1000f", "both", 0, 0, 0, -1, -1, false, ""};
  row.pass = used0 == used1 && buf0 == buf1 && alloc0 == alloc1 && r.diagnostics().syncs_last_frame == 1;
  row.note = "device used " + std::to_string(used0 >> 20) + " -> " + std::to_string(used1 >> 20) + " MiB, buffers " +
             std::to_string(buf0) + " -> " + std::to_string(buf1) + " B, allocations " + std::to_string(alloc0) +
             " -> " + std::to_string(alloc1) + ", syncs/frame " + std::to_string(r.diagnostics().syncs_last_frame);
  add(row);
}

// 5: more tiles than 16 key bits.
void tile_bits_checks(const Scenes& sc) {
  const Camera cam = orbit_views(*sc.biker, 8192, 4608)[0];
  for (Pipeline p : {Pipeline::vanilla, Pipeline::exact}) {
    catgs::RenderOptions o;
    o.pipeline = p;
    catgs::cpu::CpuRenderer c(sc.biker, o);
    catgs::cuda::CudaRenderer g(sc.biker_dev, o);
    Image a, b;
    c.render(cam, a);
    g.render(cam, b);
    const Diff d = compare(a, b);
    add({"tiles18", "sc.biker", "8192x4608", catgs::pipeline_name(p), d.psnr, d.max_abs, d.max_abs8,
         static_cast<long long>(c.last_stats().render_list_length),
         static_cast<long long>(g.last_stats().render_list_length), d.psnr >= 50.0, "147456 tiles, 18 tile bits"});
  }
}

// 6: render lists past 2^31 and past 2^32 - 1 entries.
void list_limit_checks() {
  const Camera cam = front_camera(1920, 1080);
  const std::size_t n = (std::size_t{1} << 31) / 8160 + 20000;  // ~2.3 G entries
  auto wall = wall_scene(n);
  catgs::RenderOptions o;
  o.pipeline = Pipeline::vanilla;
  o.list_budget = catgs::RenderListBudget::unlimited();  // the 2^32 - 1 limit alone
  Row row{"list>2^31", wall->name, "front", "vanilla", 0, 0, 0, -1, -1, false, ""};
  try {
    auto dev = catgs::cuda::DeviceScene::upload(*wall);
    Image big, small;
    {
      catgs::cuda::CudaRenderer r(dev, o);
      r.render(cam, big);
      row.list_gpu = static_cast<long long>(r.last_stats().render_list_length);
      row.note = "buffers " + std::to_string(r.diagnostics().peak_buffer_bytes >> 20) + " MiB";
    }
    // Only the nearest layers are visible: the first 64 Gaussians give the same image.
    auto front = wall_scene(64);
    catgs::cuda::CudaRenderer r2(catgs::cuda::DeviceScene::upload(*front), o);
    r2.render(cam, small);
    const Diff d = compare(big, small);
    row.psnr = d.psnr;
    row.max_abs = d.max_abs;
    row.max_abs8 = d.max_abs8;
    row.list_ref = static_cast<long long>(n * 8160);
    row.pass = row.list_gpu == row.list_ref && row.list_gpu > (1ll << 31) && d.psnr >= 50.0;
  } catch (const catgs::cuda::CudaError& e) {
    row.note = std::string("clean failure: ") + e.what();
    row.pass = e.code() == 2;  // cudaErrorMemoryAllocation: a clear message, no overflow
  } catch (const std::exception& e) {
    row.note = std::string("unexpected: ") + e.what();
  }
  add(row);

  const std::size_t n2 = (std::size_t{1} << 32) / 8160 + 1000;
  auto wall2 = wall_scene(n2);
  Row row2{"list>2^32", wall2->name, "front", "vanilla", 0, 0, 0, -1, -1, false, ""};
  row2.list_ref = static_cast<long long>(n2 * 8160);
  try {
    catgs::cuda::CudaRenderer r(catgs::cuda::DeviceScene::upload(*wall2), o);
    r.render_device(cam);
    row2.note = "no error: overflow not detected";
  } catch (const std::length_error& e) {
    row2.pass = true;
    row2.note = e.what();
  } catch (const std::exception& e) {
    row2.note = std::string("unexpected: ") + e.what();
  }
  add(row2);
}

// The entry count a RenderBudgetError names ("render list of N entries"), or -1.
long long refused_entries(const std::string& what) {
  const std::string lead = "render list of ";
  const auto at = what.find(lead);
  return at == std::string::npos ? -1 : std::atoll(what.c_str() + at + lead.size());
}

// One frame through `render`: the entry count of its RenderBudgetError, -1 when it drew the
// frame, -2 when it failed otherwise (the message in `note`).
template <typename Render>
long long refusal(Render&& render, std::string& note) {
  try {
    render();
    return -1;
  } catch (const catgs::RenderBudgetError& e) {
    return refused_entries(e.what());
  } catch (const std::exception& e) {
    note = std::string("unexpected: ") + e.what();
    return -2;
  }
}

// 6a: the render-list budget, CUDA as the CPU core.
void budget_checks() {
  auto wall = wall_scene(20000);
  auto dev = catgs::cuda::DeviceScene::upload(*wall);
  const Camera big = front_camera(1280, 720), small = front_camera(64, 48);
  for (const Pipeline p : {Pipeline::vanilla, Pipeline::exact, Pipeline::catgs}) {
    catgs::RenderOptions o;
    o.pipeline = p;
    Row row{"budget", wall->name, "front", catgs::pipeline_name(p), 0, 0, 0, -1, -1, false, ""};
    std::unique_ptr<catgs::Renderer> cpu;
    if (p == Pipeline::catgs)
      cpu = std::make_unique<catgs::cpu::SpeculativeRenderer>(wall, o);
    else
      cpu = std::make_unique<catgs::cpu::CpuRenderer>(wall, o);
    catgs::cuda::CudaRenderer gpu(dev, o);
    Image c, g;
    row.list_ref = refusal([&] { cpu->render(big, c); }, row.note);
    row.list_gpu = refusal([&] { gpu.render(big, g); }, row.note);
    const std::size_t held = gpu.diagnostics().buffer_bytes;  // what the refused frame grew
    const bool refused = row.list_gpu > 0 && row.list_gpu == row.list_ref &&
                         held < static_cast<std::size_t>(row.list_gpu) * catgs::cuda::kBytesPerListEntry / 10;
    // The session's renderer goes on: a small view of the same scene is within the budget.
    std::string small_note;
    const bool drew = refusal([&] { cpu->render(small, c); }, small_note) == -1 &&
                      refusal([&] { gpu.render(small, g); }, small_note) == -1;
    const Diff d = drew ? compare(c, g) : Diff{0, 0, 0};
    row.psnr = d.psnr;
    row.max_abs = d.max_abs;
    row.max_abs8 = d.max_abs8;
    row.pass = refused && drew && d.psnr >= 50.0 &&
               gpu.last_stats().render_list_length == cpu->last_stats().render_list_length;
    if (row.note.empty())
      row.note = "refused holding " + std::to_string(held >> 10) + " KiB of buffers; 64x48 after: list " +
                 std::to_string(gpu.last_stats().render_list_length) + " " + small_note;
    add(row);
  }
}

// 6d: hostile values (issue 49, tests/common/hostile_values.h) straight to the CUDA core, every 7th
// Gaussian of biker (SH 0) and flowers_sh3 (SH 3): vanilla, exact and catgs over 24 frames of a
// short orbit at WxH end in a clear error or a finite image on every frame (under
// compute-sanitizer memcheck with --sanitize: no out-of-bounds access), and CUDA exact equals the
// CPU's exact on the orbit's first view (>= 50 dB, the same list), so the two cores draw hostile
// models alike.
void hostile_checks(const Scenes& sc, int w, int h) {
  std::vector<std::pair<std::string, std::string>> scenes{{"biker", sc.dir + "/biker.compressed.ply"},
                                                          {"flowers_sh3", sc.dir + "/flowers_sh3.ply"}};
  for (const auto& [name, path] : scenes) {
    const auto base = load(path, 1.0f);
    catgs::GeneratorParams g;
    g.width = w;
    g.height = h;
    g.rate_hz = 60.0;
    g.duration_s = 23.0 / 60.0;  // 24 frames
    const auto rb = catgs::robust_bounds(*base);
    const catgs::Trace orbit = catgs::make_orbit(rb, 1.5f * glm::length(rb.extent()), 0.0f, 30.0f, g);
    for (const catgs::test::HostileCase& c : catgs::test::hostile_cases()) {
      auto m = std::make_shared<GaussianModel>(*base);
      catgs::test::apply_hostile(*m, c);
      const auto dev = catgs::cuda::DeviceScene::upload(*m);
      for (const Pipeline p : {Pipeline::vanilla, Pipeline::exact, Pipeline::catgs}) {
        catgs::RenderOptions o;
        o.pipeline = p;
        Row row{"hostile", name, c.name, catgs::pipeline_name(p), 0, 0, 0, -1, -1, false, ""};
        catgs::cuda::CudaRenderer gpu(dev, o);
        Image img;
        std::size_t frames = 0, bad = 0;
        std::string error;
        for (const catgs::TimedCamera& t : orbit) {
          try {
            gpu.render(t.camera, img);
          } catch (const std::exception& e) {
            error = e.what();
            break;
          }
          ++frames;
          bad += catgs::test::count_non_finite(img.rgb);
        }
        bool same = true;
        if (p == Pipeline::exact && error.empty()) {
          catgs::cpu::CpuRenderer cpu(m, o);
          Image a, b;
          cpu.render(orbit.front().camera, a);
          gpu.render(orbit.front().camera, b);
          const Diff d = compare(a, b);
          row.psnr = d.psnr;
          row.max_abs = d.max_abs;
          row.max_abs8 = d.max_abs8;
          row.list_ref = static_cast<long long>(cpu.last_stats().render_list_length);
          row.list_gpu = static_cast<long long>(gpu.last_stats().render_list_length);
          same = d.psnr >= 50.0 && row.list_ref == row.list_gpu;
        }
        row.pass = bad == 0 && same && (error.empty() || error.size() > 10);
        row.note = std::to_string(frames) + " frames, " + std::to_string(bad) + " non-finite values" +
                   (error.empty() ? std::string() : "; error: " + error);
        add(row);
      }
    }
  }
}

// 6c: the render-list budget's passes and narrowed windows (renderer.h, issue 35), CUDA as the CPU
// core. A budget of `limit` entries a pass at any size (min_entries alone sets it).
catgs::RenderListBudget pass_budget(std::uint64_t limit) {
  catgs::RenderListBudget b;
  b.max_entries_per_tile = 0;
  b.min_entries = limit;
  b.max_passes = 1000;
  return b;
}

void passes_checks(Scenes& sc) {
  if (!sc.biker) {
    sc.biker = load(sc.dir + "/biker.compressed.ply", 1.0f);
    sc.biker_dev = catgs::cuda::DeviceScene::upload(*sc.biker);
  }
  const auto& model = sc.biker;
  const auto& dev = sc.biker_dev;
  // vanilla, exact: a third of the list a pass; the image equals one pass (the same entries per
  // tile, sorted with the frame's key, split with its slice length) and the CPU's passes.
  const Camera cam = orbit_views(*model, sc.W, sc.H)[1];
  for (const Pipeline p : {Pipeline::vanilla, Pipeline::exact}) {
    catgs::RenderOptions o;
    o.pipeline = p;
    o.speculation.min_slice_entries = 0;  // the paper's slice length: tiles really split
    catgs::cuda::CudaRenderer one(dev, o);
    Image g1, g, c;
    one.render(cam, g1);
    const std::uint64_t entries = one.last_stats().render_list_length, limit = entries / 3;
    o.list_budget = pass_budget(limit);
    catgs::cpu::CpuRenderer cpu(model, o);
    catgs::cuda::CudaRenderer gpu(dev, o);
    cpu.render(cam, c);
    gpu.render(cam, g);
    const catgs::FrameStats &cs = cpu.last_stats(), &gs = gpu.last_stats();
    const Diff vs_cpu = compare(c, g), vs_one = compare(g, g1);
    char note[200];
    std::snprintf(note, sizeof note,
                  "%d passes (CPU %d), longest %zu of %llu a pass; vs one CUDA pass: %s dB, max abs %.3g", gs.passes,
                  cs.passes, gs.longest_pass, static_cast<unsigned long long>(limit), fmt_psnr(vs_one.psnr).c_str(),
                  vs_one.max_abs);
    add({"passes", model->name, "orbit1", catgs::pipeline_name(p), vs_cpu.psnr, vs_cpu.max_abs, vs_cpu.max_abs8,
         static_cast<long long>(cs.render_list_length), static_cast<long long>(gs.render_list_length),
         vs_cpu.psnr >= 50.0 && vs_one.psnr >= 60.0 && gs.passes >= 3 && gs.passes == cs.passes &&
             gs.longest_pass <= limit && gs.render_list_length == entries,
         note});
  }

  // catgs over an orbit (40 degrees a second, 0.3 s at 120 Hz).
  catgs::GeneratorParams gp;
  gp.width = sc.W;
  gp.height = sc.H;
  gp.duration_s = 0.3;
  gp.up = {0.0f, -1.0f, 0.0f};
  const auto rb = catgs::robust_bounds(*model);
  const glm::vec3 e = rb.extent();
  const float r = 0.6f * std::max(e.x, std::max(e.y, e.z));
  const catgs::Trace trace = catgs::make_orbit(rb, r, 0.3f * r, 12.0f, gp);
  catgs::RenderOptions o = catgs_options();
  o.speculation.min_slice_entries = 0;
  catgs::RenderOptions exact_o = o;
  exact_o.pipeline = Pipeline::exact;
  catgs::cuda::CudaRenderer exact(dev, exact_o);
  Image x;
  exact.render(trace[0].camera, x);
  const std::uint64_t exact_entries = exact.last_stats().render_list_length;
  // The unbudgeted CPU run's key-frame lists with a window: the budget goes halfway between.
  std::uint64_t shortest = UINT64_MAX, longest = 0;
  {
    catgs::cpu::SpeculativeRenderer free_run(model, o);
    Image a;
    for (const auto& tc : trace) {
      free_run.render_at(tc.camera, tc.time_s, a);
      const catgs::FrameStats& st = free_run.last_stats();
      if (st.key_frame && st.window > 0) {
        shortest = std::min<std::uint64_t>(shortest, st.render_list_length);
        longest = std::max<std::uint64_t>(longest, st.render_list_length);
      }
    }
  }
  for (const bool fallback : {true, false}) {
    // fallback: a third of the exact list, so every key frame falls back to an exact frame in
    // passes (compared with the unbudgeted CUDA exact frame of its pose); narrowed: halfway between
    // the windowed key lists, so the longer ones narrow (CPU and CUDA must narrow alike).
    const std::uint64_t limit = fallback ? exact_entries / 3 : shortest + (longest - shortest) / 2;
    catgs::RenderOptions bo = o;
    bo.list_budget = pass_budget(limit);
    catgs::cpu::SpeculativeRenderer cpu(model, bo);
    catgs::cuda::CudaRenderer gpu(dev, bo);
    Image c, g;
    int agree = 0, narrowed = 0, in_passes = 0;
    double min_psnr = 1e9, min_vs_exact = 1e9, max_abs = 0;
    int max_abs8 = 0;
    for (const auto& tc : trace) {
      cpu.render_at(tc.camera, tc.time_s, c);
      gpu.render_at(tc.camera, tc.time_s, g);
      const catgs::FrameStats &cs = cpu.last_stats(), &gs = gpu.last_stats();
      const bool same = cs.key_frame == gs.key_frame && cs.window == gs.window &&
                        cs.window_narrowed == gs.window_narrowed && cs.passes == gs.passes;
      agree += same ? 1 : 0;
      narrowed += gs.window_narrowed ? 1 : 0;
      in_passes += gs.passes > 1 ? 1 : 0;
      if (same) {
        const Diff d = compare(c, g);
        min_psnr = std::min(min_psnr, d.psnr);
        max_abs = std::max(max_abs, d.max_abs);
        max_abs8 = std::max(max_abs8, d.max_abs8);
      }
      if (fallback) {
        exact.render(tc.camera, x);
        min_vs_exact = std::min(min_vs_exact, compare(g, x).psnr);
      }
    }
    const int frames = static_cast<int>(trace.size());
    char note[200];
    std::snprintf(note, sizeof note, "limit %llu: %d/%d frames agree, %d narrowed, %d in passes%s%s",
                  static_cast<unsigned long long>(limit), agree, frames, narrowed, in_passes,
                  fallback ? "; vs unbudgeted CUDA exact min " : "",
                  fallback ? (fmt_psnr(min_vs_exact) + " dB").c_str() : "");
    const bool pass = 100 * agree >= 95 * frames && min_psnr >= 50.0 &&
                      (fallback ? in_passes == frames && min_vs_exact >= 60.0 : narrowed > 0 && shortest < longest);
    add({"passes", model->name, fallback ? "orbit-fb" : "orbit-nw", "catgs", min_psnr, max_abs, max_abs8,
         static_cast<long long>(cpu.last_stats().render_list_length),
         static_cast<long long>(gpu.last_stats().render_list_length), pass, note});
  }
}

// 6b: more huge Gaussians than key emission keeps part counts for (tunables.h kHugeListed): the
// first kHugeListed are counted and emitted a block per part, the rest a block each. Every
// Gaussian of the wall covers the whole image, so each is huge; the list and image must be the
// CPU reference's.
void huge_checks() {
  const Camera cam = front_camera(640, 360);
  auto wall = wall_scene(static_cast<std::size_t>(catgs::cuda::tune::kHugeListed) + 2000);
  catgs::RenderOptions o;
  o.pipeline = Pipeline::exact;
  o.list_budget.max_entries_per_tile = 1u << 20;  // 18 k entries a tile
  catgs::cpu::CpuRenderer cpu(wall, o);
  catgs::cuda::CudaRenderer gpu(catgs::cuda::DeviceScene::upload(*wall), o);
  Image c, g;
  cpu.render(cam, c);
  gpu.render(cam, g);
  const Diff d = compare(c, g);
  const auto lc = static_cast<long long>(cpu.last_stats().render_list_length);
  const auto lg = static_cast<long long>(gpu.last_stats().render_list_length);
  add({"huge", wall->name, "front", "exact", d.psnr, d.max_abs, d.max_abs8, lc, lg, d.psnr >= 50.0 && lc == lg,
       std::to_string(wall->size()) + " Gaussians of 920 tiles each"});
}

// 7: tens of millions of Gaussians (49 copies), CUDA == CPU on a fly-over view.
// The city of tumblewood copies within `radius_sq` cells of the centre (tools/scene_tools/city.h),
// and a fly-over camera over it with `flight`'s parameters at the tests' size.
struct TestCity {
  std::shared_ptr<GaussianModel> model;
  catgs::CityLayout layout;
  Camera view(const Scenes& sc, const catgs::FlyoverParams& flight) const {
    catgs::GeneratorParams g;
    g.width = sc.W;
    g.height = sc.H;
    g.duration_s = 1.0;
    g.rate_hz = 2.0;
    return catgs::make_city_flyover(layout, flight, g)[1].camera;
  }
};
TestCity test_city(const Scenes& sc, int radius_sq) {
  catgs::CityParams p;
  p.radius_sq = radius_sq;
  p.up = {0.0f, -1.0f, 0.0f};
  TestCity c;
  auto base = catgs::load_scene(sc.dir + "/tumblewood_sh2.compressed.ply");
  c.model = std::make_shared<GaussianModel>(catgs::tile_scene(base, p, &c.layout));
  return c;
}

void city_checks(const Scenes& sc) {
  const TestCity tc = test_city(sc, 16);  // 49 cells
  const auto& city = tc.model;
  const Camera fly = tc.view(sc, catgs::FlyoverParams{});
  auto dev = catgs::cuda::DeviceScene::upload(*city);
  for (Pipeline pl : {Pipeline::vanilla, Pipeline::exact}) {
    catgs::RenderOptions o;
    o.pipeline = pl;
    catgs::cpu::CpuRenderer c(city, o);
    catgs::cuda::CudaRenderer r(dev, o);
    Image a, b;
    c.render(fly, a);
    r.render(fly, b);
    const Diff d = compare(a, b);
    add({"city", city->name, "fly1", catgs::pipeline_name(pl), d.psnr, d.max_abs, d.max_abs8,
         static_cast<long long>(c.last_stats().render_list_length),
         static_cast<long long>(r.last_stats().render_list_length), d.psnr >= 50.0,
         std::to_string(city->size()) + " Gaussians, " + std::to_string(dev->bytes() >> 20) + " MiB on device"});
  }
}

// 8: chunk culling's kept-chunk list (preprocess.cu cull_chunks_kernel) against the CPU, after a
// frame that listed chunks this one culls (their tile counts are stale: records.h listed_tiles).
void chunk_cull_checks(const Scenes& sc) {
  const TestCity tc = test_city(sc, 4);  // 13 cells
  const auto& city = tc.model;
  catgs::FlyoverParams centre;  // catgs-bench --trace centre
  centre.altitude = 0.4f;
  centre.pitch_deg = 70.0f;
  centre.start_cells = -0.25f;
  centre.end_cells = 0.25f;
  const Camera wide = tc.view(sc, catgs::FlyoverParams{}), narrow = tc.view(sc, centre);
  auto dev = catgs::cuda::DeviceScene::upload(*city);
  catgs::RenderOptions o;
  o.pipeline = Pipeline::exact;
  catgs::cpu::CpuRenderer cpu(city, o);
  for (bool depth_first : {false, true}) {
    catgs::cuda::CudaOptions co;
    co.depth_first_sort = depth_first;
    catgs::cuda::CudaRenderer gpu(dev, o, co);
    const char* views[2] = {"fly1", "centre1"};
    for (int v = 0; v < 2; ++v) {
      const Camera& cam = v == 0 ? wide : narrow;
      Image a, b;
      cpu.render(cam, a);
      gpu.render(cam, b);
      const Diff d = compare(a, b);
      const auto lc = static_cast<long long>(cpu.last_stats().render_list_length);
      const auto lg = static_cast<long long>(gpu.last_stats().render_list_length);
      const auto diag = gpu.diagnostics();
      const bool culled = v == 0 || 2 * diag.chunks_kept < diag.chunks;
      add({"chunkcull", city->name, views[v], depth_first ? "ex/depth" : "exact", d.psnr, d.max_abs, d.max_abs8, lc, lg,
           d.psnr >= 50.0 && lc == lg && culled,
           std::to_string(diag.chunks_kept) + " of " + std::to_string(diag.chunks) + " chunks kept"});
    }
  }
}

// 9: level of detail (forward_model/lod.h): the cut both cores take, CUDA against the CPU.
void lod_checks(const Scenes& sc) {
  const TestCity tc = test_city(sc, 4);  // 13 cells
  catgs::LodBuildReport built;
  const auto lod = std::make_shared<GaussianModel>(catgs::build_lod(*tc.model, {}, &built));
  // The scene without LOD in the LOD's leaf order (Morton), for the bit-for-bit check at tau 0.
  const auto full = std::make_shared<GaussianModel>(catgs::permuted(*tc.model, catgs::morton_order(*tc.model)));
  auto dev = catgs::cuda::DeviceScene::upload(*lod);
  auto dev_full = catgs::cuda::DeviceScene::upload(*full);
  catgs::GeneratorParams g;
  g.width = sc.W;
  g.height = sc.H;
  g.duration_s = 0.5;  // 61 frames: the CPU's catgs frames of 7 M Gaussians take the time
  g.rate_hz = 120.0;
  const catgs::Trace trace = catgs::make_city_flyover(tc.layout, catgs::FlyoverParams{}, g);
  catgs::RenderOptions o;
  o.pipeline = Pipeline::exact;
  const std::string levels = std::to_string(lod->size()) + " Gaussians, " + std::to_string(built.level_nodes.size()) +
                             " levels, built in " + std::to_string(built.seconds) + " s";
  constexpr float kCoarse = 4.0f;  // a bound that draws many merged chunks on this city
  for (float bound : {o.lod_error_px, kCoarse}) {
    catgs::RenderOptions ob = o;
    ob.lod_error_px = bound;
    catgs::cpu::CpuRenderer cpu(lod, ob);
    catgs::cuda::CudaRenderer gpu(dev, ob);
    for (std::size_t k = 0; k < trace.size(); k += trace.size() / 4) {
      Image a, b;
      cpu.render(trace[k].camera, a);
      gpu.render(trace[k].camera, b);
      const Diff d = compare(a, b);
      const auto lc = static_cast<long long>(cpu.last_stats().render_list_length);
      const auto lg = static_cast<long long>(gpu.last_stats().render_list_length);
      add({"lod", lod->name, "fly" + std::to_string(k), "exact@" + std::to_string(static_cast<int>(bound)), d.psnr,
           d.max_abs, d.max_abs8, lc, lg, d.psnr >= 50.0 && lc == lg, levels});
    }
  }
  {  // tau 0: the leaves only, the scene as it was
    catgs::RenderOptions zero = o, coarse = o;
    zero.lod_error_px = 0.0f;
    coarse.lod_error_px = kCoarse;
    catgs::cuda::CudaRenderer a_gpu(dev, zero), b_gpu(dev_full, zero), tau_gpu(dev, coarse);
    Image a, b, t;
    const Camera& cam = trace[trace.size() / 2].camera;
    a_gpu.render(cam, a);
    b_gpu.render(cam, b);
    tau_gpu.render(cam, t);
    const Diff d = compare(a, b);
    const auto kept_lod = tau_gpu.diagnostics().chunks_kept, kept_full = b_gpu.diagnostics().chunks_kept;
    add({"lod", lod->name, "tau0", "exact", d.psnr, d.max_abs, d.max_abs8,
         static_cast<long long>(b_gpu.last_stats().render_list_length),
         static_cast<long long>(a_gpu.last_stats().render_list_length), d.max_abs == 0.0 && kept_lod < kept_full,
         "vs the scene without LOD; chunks kept at 4 px " + std::to_string(kept_lod) + ", without LOD " +
             std::to_string(kept_full)});
  }
  catgs::RenderOptions co = o;
  co.pipeline = Pipeline::catgs;
  co.lod_error_px = kCoarse;
  catgs::cpu::SpeculativeRenderer cpu(lod, co);
  catgs::cuda::CudaRenderer gpu(dev, co);
  std::size_t agree = 0, subs = 0;
  double min_psnr = INFINITY, max_abs = 0;
  int max8 = 0;
  for (const auto& f : trace) {
    Image a, b;
    cpu.render_at(f.camera, f.time_s, a);
    gpu.render_at(f.camera, f.time_s, b);
    if (cpu.last_stats().key_frame != gpu.last_stats().key_frame) continue;
    ++agree;
    subs += gpu.last_stats().key_frame ? 0 : 1;
    const Diff d = compare(a, b);
    min_psnr = std::min(min_psnr, d.psnr);
    max_abs = std::max(max_abs, d.max_abs);
    max8 = std::max(max8, d.max_abs8);
  }
  char note[160];
  std::snprintf(note, sizeof note, "%zu frames: decisions agree on %zu (%zu sub-frames)", trace.size(), agree, subs);
  add({"lod", lod->name, "flyover", "catgs@4", min_psnr, max_abs, max8, -1, -1,
       agree * 100 >= trace.size() * 95 && min_psnr >= 50.0 && subs > 0, note});
}

// The table (markdown) of every check, to `out` if given; returns the number that failed.
int report(const std::string& gpu, const std::string& out) {
  int failed = 0;
  std::ostringstream md;
  md << "GPU: " << gpu
     << "\n\n| test | scene | view | pipeline | PSNR dB | max abs err (float) | max abs err (8-bit) | "
        "render list (ref) | render list (GPU) | result | note |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const Row& r : g_rows) {
    failed += r.pass ? 0 : 1;
    char err[32];
    std::snprintf(err, sizeof err, "%.3g", r.max_abs);
    md << "| " << r.test << " | " << r.scene << " | " << r.view << " | " << r.pipeline << " | " << fmt_psnr(r.psnr)
       << " | " << err << " | " << r.max_abs8 << " | " << r.list_ref << " | " << r.list_gpu << " | "
       << (r.pass ? "PASS" : "FAIL") << " | " << r.note << " |\n";
  }
  md << "\n" << (g_rows.size() - static_cast<std::size_t>(failed)) << " passed, " << failed << " failed\n";
  if (!out.empty()) std::ofstream(out) << md.str();
  std::printf("%zu checks: %zu passed, %d failed\n", g_rows.size(), g_rows.size() - static_cast<std::size_t>(failed),
              failed);
  return failed;
}

int run(int argc, char** argv) {
  const catgs::tools::Args args(argc, argv, {"--scenes", "--traces", "--out", "--quick!", "--skip-large!", "--only"});
  std::string why;
  if (!catgs::cuda::device_usable(&why)) {
    std::fprintf(stderr, "no usable CUDA device: %s\n", why.c_str());
    return 2;
  }
  const std::string gpu = catgs::cuda::device_description();
  Scenes sc;
  sc.dir = args.require("--scenes");
  sc.traces = args.get("--traces", sc.dir);
  sc.quick = args.has("--quick");
  sc.W = sc.quick ? 640 : 1280;
  sc.H = sc.quick ? 360 : 720;
  std::printf("GPU: %s\n", gpu.c_str());
  std::printf("%-10s %-16s %-7s %-8s %8s %10s %4s %12s %12s  %s\n", "test", "scene", "view", "pipeline", "PSNR dB",
              "max|err|", "8bit", "list (ref)", "list (gpu)", "result");
  if (args.get("--only", "") == "budget") {  // the budget rows alone (they need no scene files)
    budget_checks();
    return report(gpu, args.get("--out", "")) == 0 ? 0 : 1;
  }
  if (args.get("--only", "") == "lod") {  // the level of detail rows alone (tumblewood)
    lod_checks(sc);
    return report(gpu, args.get("--out", "")) == 0 ? 0 : 1;
  }
  if (args.get("--only", "") == "hostile") {  // hostile values (issue 49; biker and flowers_sh3)
    hostile_checks(sc, sc.quick ? 320 : 1280, sc.quick ? 180 : 720);
    return report(gpu, args.get("--out", "")) == 0 ? 0 : 1;
  }
  if (args.get("--only", "") == "passes") {  // the budget's passes and narrowed windows (biker only)
    budget_checks();
    passes_checks(sc);
    return report(gpu, args.get("--out", "")) == 0 ? 0 : 1;
  }
  equality_checks(sc);
  if (!sc.quick) grow_checks(sc);
  catgs_checks(sc);
  yuv420_checks(sc);
  if (!sc.quick) steady_checks(sc);
  if (!sc.quick) huge_checks();
  if (!sc.quick) budget_checks();
  if (!sc.quick) hostile_checks(sc, sc.W, sc.H);
  if (!sc.quick) passes_checks(sc);
  if (!sc.quick) chunk_cull_checks(sc);
  if (!sc.quick) lod_checks(sc);
  if (!sc.quick && !args.has("--skip-large")) {
    tile_bits_checks(sc);
    list_limit_checks();
    city_checks(sc);
  }
  return report(gpu, args.get("--out", "")) == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "catgs-gpu-tests: %s\n", e.what());
    return 1;
  }
}
