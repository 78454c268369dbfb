// batch: stage 1 of several renderers' frames in one pass (CudaRenderer::preprocess_batch,
// preprocess.cu preprocess_batch; issue 47). 16 views spread along a real camera path, each drawn
// by a renderer of its own after one batched pre-processing, against the same views drawn one at
// a time by a single renderer: the same image bit for bit (float RGB and RGBA8) and the same
// render list; two of them also against the CPU reference (>= 50 dB, the same list). Then a
// second round on the same renderers (their buffers hold the first round's results) with views of
// two sizes, and a renderer whose frame is not the camera it was batched for (it pre-processes
// again). Exact and vanilla, on flowers along its own path and on tumblewood x10 along the
// bicycle path.
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "gpu_test_support.h"

namespace catgs::gputest {
namespace {

bool same_image(const Image& a, const Image& b) {
  return a.width == b.width && a.height == b.height && a.rgba8 == b.rgba8 && a.rgb.size() == b.rgb.size() &&
         std::memcmp(a.rgb.data(), b.rgb.data(), a.rgb.size() * sizeof(float)) == 0;
}

// `count` cameras spread evenly along `trace`, every `small`-th (k % small == 1) at half size.
std::vector<Camera> spread(const catgs::Trace& trace, std::size_t count, std::size_t offset, int small) {
  std::vector<Camera> views;
  for (std::size_t k = 0; k < count; ++k) {
    Camera c = trace[(offset + k * trace.size() / count) % trace.size()].camera;
    if (small > 0 && k % small == 1) c = c.rescaled(c.width / 2, c.height / 2);
    views.push_back(c);
  }
  return views;
}

void batch_check(const SharedScene& scene, const std::string& path, Pipeline pipeline) {
  const int W = config().W, H = config().H;
  const std::size_t views = config().quick ? 4 : 16;
  const catgs::Trace trace = real_trace(*scene.model, trace_path(path), W, H, 480);
  catgs::RenderOptions o;
  o.pipeline = pipeline;
  std::vector<std::unique_ptr<catgs::cuda::CudaRenderer>> owned;
  std::vector<catgs::cuda::CudaRenderer*> batch;
  for (std::size_t k = 0; k < views; ++k) {
    owned.push_back(std::make_unique<catgs::cuda::CudaRenderer>(scene.dev, o));
    batch.push_back(owned.back().get());
  }
  catgs::cuda::CudaRenderer alone(scene.dev, o);
  catgs::cpu::CpuRenderer cpu(scene.model, o);
  const char* name = pipeline == Pipeline::exact ? "exact" : "vanilla";
  // Round 0: one size; round 1: the same renderers, other views, every 4th at half size, and the
  // last renderer asked for another camera than its batched one.
  for (int round = 0; round < 2; ++round) {
    const std::vector<Camera> cams = spread(trace, views, round * 7, round == 0 ? 0 : 4);
    catgs::cuda::CudaRenderer::preprocess_batch(batch, cams);
    int identical = 0, lists_equal = 0;
    std::string note;
    for (std::size_t k = 0; k < views; ++k) {
      const bool moved = round == 1 && k + 1 == views;
      const Camera cam = moved ? trace[(k * 31 + 5) % trace.size()].camera : cams[k];
      Image got, want;
      batch[k]->render(cam, got);
      const auto list_batch = static_cast<long long>(batch[k]->last_stats().render_list_length);
      alone.render(cam, want);
      const auto list_alone = static_cast<long long>(alone.last_stats().render_list_length);
      identical += same_image(got, want) ? 1 : 0;
      lists_equal += list_batch == list_alone ? 1 : 0;
      if (k == 0 || k == views / 2) {  // the CPU reference too
        Image ref;
        cpu.render(cam, ref);
        const Diff d = compare(ref, got);
        const auto list_cpu = static_cast<long long>(cpu.last_stats().render_list_length);
        add({"batch", scene.model->name, path + " r" + std::to_string(round) + " v" + std::to_string(k), name, d.psnr,
             d.max_abs, d.max_abs8, list_cpu, list_batch, d.psnr >= 50.0 && list_cpu == list_batch,
             "batched view vs the CPU reference, " + std::to_string(cam.width) + "x" + std::to_string(cam.height)});
      }
    }
    note = std::to_string(identical) + " of " + std::to_string(views) + " images identical to one-at-a-time, " +
           std::to_string(lists_equal) + " lists equal" + (round == 1 ? " (mixed sizes, one moved camera)" : "");
    add({"batch", scene.model->name, path + " r" + std::to_string(round), name, 0, 0, 0, -1, -1,
         identical == static_cast<int>(views) && lists_equal == static_cast<int>(views), note});
  }
}

class Batch : public GpuTest {};

TEST_F(Batch, FlowersOwnPath) {
  CATGS_GPU_REQUIRE({"flowers_sh3"}, {"flowers_sh3"});
  batch_check(flowers(), "flowers_sh3", Pipeline::exact);
  batch_check(flowers(), "flowers_sh3", Pipeline::vanilla);
}

TEST_F(Batch, TumblewoodBicycle) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"}, {"mipnerf360_bicycle"});
  batch_check(tumblewood(), "mipnerf360_bicycle", Pipeline::exact);
}

TEST_F(Batch, Refusals) {
  CATGS_GPU_REQUIRE({"biker", "flowers_sh3"});
  catgs::RenderOptions exact, vanilla, catgs_o = catgs_options();
  vanilla.pipeline = Pipeline::vanilla;
  catgs::cuda::CudaRenderer a(biker().dev, exact), b(biker().dev, exact), v(biker().dev, vanilla),
      c(biker().dev, catgs_o), f(flowers().dev, exact);
  const Camera cam = orbit_views(*biker().model, 320, 180)[0];
  using R = catgs::cuda::CudaRenderer;
  int refused = 0;
  auto refuses = [&](const std::vector<R*>& rs, const std::vector<Camera>& cs) {
    try {
      R::preprocess_batch(rs, cs);
    } catch (const std::invalid_argument&) {
      ++refused;
    }
  };
  refuses({&a, &a}, {cam, cam});              // the same renderer twice
  refuses({&a, &f}, {cam, cam});              // another scene
  refuses({&a, &v}, {cam, cam});              // exact beside vanilla
  refuses({&a, &c}, {cam, cam});              // catgs
  refuses({&a, &b}, {cam});                   // counts differ
  refuses({}, {});                            // empty
  R::preprocess_batch({&a, &b}, {cam, cam});  // fine
  Image x, y;
  a.render(cam, x);
  b.render(cam, y);
  // New options drop a batch's stage 1: batched as exact, drawn as vanilla, it must be vanilla's.
  R::preprocess_batch({&a, &b}, {cam, cam});
  a.set_options(vanilla);
  Image switched, want;
  a.render(cam, switched);
  v.render(cam, want);
  add({"batch", "biker", "refusals", "exact", 0, 0, 0, -1, -1,
       refused == 6 && same_image(x, y) && same_image(switched, want),
       std::to_string(refused) + " of 6 bad batches refused; a good one after them draws; a renderer whose "
                                 "options changed after its batch draws as a fresh one"});
}

}  // namespace
}  // namespace catgs::gputest
