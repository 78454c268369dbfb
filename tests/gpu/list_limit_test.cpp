// Render lists past 32 bits (label gpu_large), vanilla at 1920x1080 on walls of huge Gaussians:
//  list>2^31  a render list of more than 2^31 entries renders (the image of the first 64
//             Gaussians, >= 50 dB, the list n * 8160 entries), or fails with a clear CudaError
//             for lack of device memory;
//  list>2^32  more than 2^32 - 1 entries throws std::length_error.
#include <cstddef>
#include <exception>
#include <stdexcept>
#include <string>

#include "gpu_test_support.h"

namespace catgs::gputest {
namespace {

catgs::RenderOptions unlimited_vanilla() {
  catgs::RenderOptions o;
  o.pipeline = Pipeline::vanilla;
  o.list_budget = catgs::RenderListBudget::unlimited();  // the 2^32 - 1 limit alone
  return o;
}

class ListLimit : public GpuTest {};

TEST_F(ListLimit, Past2To31) {
  const Camera cam = front_camera(1920, 1080);
  const std::size_t n = (std::size_t{1} << 31) / 8160 + 20000;  // ~2.3 G entries
  auto wall = wall_scene(n);
  const catgs::RenderOptions o = unlimited_vanilla();
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
}

TEST_F(ListLimit, Past2To32) {
  const Camera cam = front_camera(1920, 1080);
  const std::size_t n2 = (std::size_t{1} << 32) / 8160 + 1000;
  auto wall2 = wall_scene(n2);
  const catgs::RenderOptions o = unlimited_vanilla();
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

}  // namespace
}  // namespace catgs::gputest
