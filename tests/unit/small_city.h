// A small city of a real scene and its LOD, shared by the LOD tests of the render core and of the
// server (tests/unit/lod_test.cpp, tests/unit/server/lod_bound_test.cpp).
#pragma once

#include <memory>
#include <vector>

#include "camera/camera.h"
#include "scene/gaussian_model.h"

namespace catgs::test {

struct SmallCity {
  // 9 copies of flowers_sh3 (the cells i^2 + j^2 <= 2, up -y, scene_tools/city.h) in Morton order:
  // the LOD's leaves without padding.
  std::shared_ptr<const GaussianModel> full;
  std::shared_ptr<const GaussianModel> lod;  // build_lod(full)
  std::vector<Camera> views;                 // 9 fly-over poses at 320x180, from outside to the middle
};

// Built once per test process. Needs the real data (scenes/flowers_sh3.ply): callers check it with
// CATGS_REQUIRE_DATA first; without it, throws std::runtime_error.
const SmallCity& small_flowers_city();

}  // namespace catgs::test
