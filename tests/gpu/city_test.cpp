// city26M (label gpu_large): 49 tumblewood copies (26.6 M Gaussians), CUDA == CPU on a fly-over
// view (>= 50 dB), vanilla and exact.
#include <memory>
#include <string>

#include "gpu_test_support.h"

namespace catgs::gputest {
namespace {

// The city and its upload, built once per process.
struct City49 {
  TestCity tc;
  std::shared_ptr<const catgs::cuda::DeviceScene> dev;
};
const City49& city49() {
  static const City49 c = [] {
    City49 k;
    k.tc = test_city(16);  // 49 cells
    k.dev = catgs::cuda::DeviceScene::upload(*k.tc.model);
    return k;
  }();
  return c;
}

void city_check(Pipeline pl) {
  const TestCity& tc = city49().tc;
  const auto& city = tc.model;
  const Camera fly = tc.view(catgs::FlyoverParams{});
  const auto& dev = city49().dev;
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

class City : public GpuTest {};

TEST_F(City, Vanilla) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  city_check(Pipeline::vanilla);
}

TEST_F(City, Exact) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  city_check(Pipeline::exact);
}

}  // namespace
}  // namespace catgs::gputest
