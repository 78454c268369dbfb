// budget: the render-list budget (renderer.h; issue 22): 20 k whole-image Gaussians at 1280x720
// (72 M entries, over the default 59 M) are refused by CUDA vanilla, exact and catgs with
// RenderBudgetError naming the same entry count as the CPU core's refusal, before any list buffer
// grows (buffers held under a tenth of the list's 24 bytes an entry); the same renderer then draws
// the scene at 64x48 (within the budget) equal to the CPU (>= 50 dB, the same list). Needs no
// scene files.
#include <cstdlib>
#include <exception>
#include <memory>
#include <string>

#include "gpu_test_support.h"

namespace catgs::gputest {
namespace {

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

// The render-list budget, CUDA as the CPU core, for pipeline `p`.
void budget_check(Pipeline p) {
  auto wall = wall_scene(20000);
  auto dev = catgs::cuda::DeviceScene::upload(*wall);
  const Camera big = front_camera(1280, 720), small = front_camera(64, 48);
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
  row.pass =
      refused && drew && d.psnr >= 50.0 && gpu.last_stats().render_list_length == cpu->last_stats().render_list_length;
  if (row.note.empty())
    row.note = "refused holding " + std::to_string(held >> 10) + " KiB of buffers; 64x48 after: list " +
               std::to_string(gpu.last_stats().render_list_length) + " " + small_note;
  add(row);
}

class Budget : public GpuTest {};

TEST_F(Budget, Vanilla) { budget_check(Pipeline::vanilla); }
TEST_F(Budget, Exact) { budget_check(Pipeline::exact); }
TEST_F(Budget, Catgs) { budget_check(Pipeline::catgs); }

}  // namespace
}  // namespace catgs::gputest
