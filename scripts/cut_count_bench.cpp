// cut_count_bench SCENE RADIUS_SQ CAMERAS.json [OUT.json]: what the splat budget's count of a
// frame's cut costs on the host (server/render/lod_bound.h CutCounter, run per frame of each
// session with a budget): a city of SCENE's copies (scene_tools/city.h, x10, up -y), its LOD
// built in memory, 100 poses of the real path CAMERAS at 1280x720; per bound, the mean ms of one
// count and of the chooser's two bounds in one walk (the bound and x sqrt(2)), and the mean
// predicted Gaussians. Standalone, against the CPU build (docs/history/level_of_detail.md "The
// cut's count on the host"):
//   B=build/cpu; g++ -std=c++20 -O3 -DNDEBUG -Irender_core -Iserver -Itools -I$B -I$B/render_core \
//     scripts/cut_count_bench.cpp -o /tmp/cut_count_bench $B/server/libcatgs_server_lib.a \
//     $B/tools/libcatgs_tool_support.a $B/render_core/libcatgs_renderers.a $B/render_core/libcatgs_render_core.a \
//     -lz -lzstd -lwebp -lzip -lstb -pthread
//   /tmp/cut_count_bench ../shared/data/scenes/tumblewood_sh2.ply 16 ../shared/data/traces/mipnerf360_bicycle.cameras.json
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>

#include "camera/trace.h"
#include "lod/lod_build.h"
#include "render/lod_bound.h"
#include "scene/ply_io.h"
#include "scene_tools/city.h"

using namespace catgs;

template <class F>
double mean_ms(F f, int reps) {
  const auto a = std::chrono::steady_clock::now();
  for (int r = 0; r < reps; ++r) f();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count() / reps;
}

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: cut_count_bench SCENE RADIUS_SQ CAMERAS.json [OUT.json]\n");
    return 1;
  }
  CityParams p;
  p.radius_sq = std::atoi(argv[2]);
  p.up = glm::vec3(0.0f, -1.0f, 0.0f);
  CityLayout layout;
  const GaussianModel lod = build_lod(tile_scene(load_scene(argv[1]), p, &layout), {});
  const Trace trace = fit_trace_to_scene(load_inria_cameras(argv[3]), lod, layout.up, 0.6f, 120.0, 0.5, 1280, 720);
  const server::CutCounter counter(lod);
  std::printf(
      "%zu Gaussians with LOD, %zu nodes\n| bound px | one count ms | two bounds ms | predicted M "
      "|\n|---|---|---|---|\n",
      lod.size(), lod.lod.size());
  std::string json = "[";
  for (const float tau : {2.0f, 4.0f, 5.66f}) {
    double one = 0, two = 0, predicted = 0;
    int n = 0;
    for (std::size_t k = 0; k < trace.size() && n < 100; k += 6, ++n) {
      const Camera& c = trace[k].camera;
      std::uint64_t count = 0;
      one += mean_ms([&] { count = counter.splats(c, tau); }, 3);
      two += mean_ms([&] { counter.splats(c, tau * 1.41421356f, tau); }, 3);
      predicted += static_cast<double>(count);
    }
    std::printf("| %.2f | %.3f | %.3f | %.3f |\n", tau, one / n, two / n, predicted / n / 1e6);
    char row[160];
    std::snprintf(row, sizeof row, "%s{\"bound_px\": %.2f, \"one_ms\": %.4f, \"two_ms\": %.4f, \"predicted\": %.0f}",
                  json.size() > 1 ? ", " : "", tau, one / n, two / n, predicted / n);
    json += row;
  }
  if (argc > 4) std::ofstream(argv[4]) << json << "]\n";
  return 0;
}
