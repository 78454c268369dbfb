#include "small_city.h"

#include <stdexcept>

#include "camera/trace.h"
#include "lod/lod_build.h"
#include "scene/morton.h"
#include "scene_tools/city.h"
#include "test_data.h"

namespace catgs::test {

const SmallCity& small_flowers_city() {
  static const SmallCity city = [] {
    const std::string path = data_file("scenes/flowers_sh3.ply");
    if (path.empty()) throw std::runtime_error("small_flowers_city: scenes/flowers_sh3.ply not found");
    SmallCity c;
    CityParams p;
    p.radius_sq = 2;  // 9 copies: the cells with i^2 + j^2 <= 2
    p.up = glm::vec3(0.0f, -1.0f, 0.0f);
    CityLayout layout;
    const GaussianModel tiled = tile_scene(*cached_scene(path), p, &layout);
    auto full = std::make_shared<GaussianModel>(permuted(tiled, morton_order(tiled)));
    c.lod = std::make_shared<const GaussianModel>(build_lod(*full));
    c.full = std::move(full);
    GeneratorParams g;
    g.width = 320;
    g.height = 180;
    g.rate_hz = 120.0;
    g.duration_s = 1.0;
    g.up = layout.up;
    FlyoverParams far = {};
    far.start_cells = -3.0f;  // from outside the city towards its middle
    far.end_cells = 0.0f;
    const Trace t = make_city_flyover(layout, far, g);
    for (std::size_t k = 0; k < t.size(); k += t.size() / 8) c.views.push_back(t[k].camera);
    return c;
  }();
  return city;
}

}  // namespace catgs::test
