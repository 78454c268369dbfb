// catgs-render: renders views of a scene to PNG with any renderer and pipeline.
//
//   catgs-render --scene S.ply --cameras C.json --view K --width W --height H
//                --pipeline vanilla|exact --renderer cpu|cuda|auto --out F.png
//   catgs-render --scene S.ply --cameras C.json --all --fps 30 --out-dir DIR    (interpolated path)
//   catgs-render --scene S.ply --trace T.trace --out-dir DIR [--every N]
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "common/image_io.h"
#include "scene/ply_io.h"
#include "renderer/renderer.h"
#include "camera/trace.h"
#include "common/cli_args.h"

namespace {

const char* kUsage =
    "usage: catgs-render --scene FILE (--cameras CAMERAS.json [--view K | --all [--fps F]] |\n"
    "                    --trace FILE.trace) [--width W] [--height H]\n"
    "                    [--pipeline vanilla|exact] [--renderer cpu|cuda|auto]\n"
    "                    [--background R,G,B] (--out FILE.png | --out-dir DIR) [--every N]\n";

int run(int argc, char** argv) {
  using catgs::tools::Args;
  const Args args(argc, argv,
                  {"--scene", "--cameras", "--view", "--all!", "--fps", "--trace", "--width", "--height", "--pipeline",
                   "--renderer", "--background", "--out", "--out-dir", "--every", "--help!"});
  if (args.has("--help")) {
    std::cout << kUsage;
    return 0;
  }
  auto model = std::make_shared<catgs::GaussianModel>(catgs::load_scene(args.require("--scene")));
  catgs::RenderOptions options;
  options.pipeline = catgs::parse_pipeline(args.get("--pipeline", "exact"));
  if (args.has("--background")) {
    float r, g, b;
    if (std::sscanf(args.get("--background").c_str(), "%f,%f,%f", &r, &g, &b) != 3)
      throw std::invalid_argument("--background wants R,G,B in [0, 1]");
    options.background = {r, g, b};
  }
  std::string why;
  auto renderer = catgs::make_renderer(args.get("--renderer", "cpu"), model, options, &why);
  std::cerr << "scene " << model->name << ": " << model->size() << " Gaussians, SH degree " << model->sh_degree << "; "
            << why << "\n";
  const int width = args.get_int("--width", 0), height = args.get_int("--height", 0);

  catgs::Trace trace;
  if (args.has("--trace")) {
    trace = catgs::read_trace(args.get("--trace"));
    if (width > 0 && height > 0)
      for (auto& tc : trace) tc.camera = tc.camera.rescaled(width, height);
  } else {
    const auto cams = catgs::load_inria_cameras(args.require("--cameras"), width, height);
    if (args.has("--all")) {
      trace = catgs::interpolate_views(cams, args.get_double("--fps", 30.0), 1.0);
    } else {
      const int k = args.get_int("--view", 0);
      if (k < 0 || k >= static_cast<int>(cams.size()))
        throw std::invalid_argument("--view " + std::to_string(k) + " outside 0.." + std::to_string(cams.size() - 1));
      trace.push_back({0.0, cams[static_cast<std::size_t>(k)]});
    }
  }

  catgs::Image image;
  if (args.has("--out")) {
    renderer->render(trace.front().camera, image);
    catgs::write_png(image, args.get("--out"));
    const auto& s = renderer->last_stats();
    std::cerr << "wrote " << args.get("--out") << " (" << image.width << "x" << image.height << ", " << s.total_ms
              << " ms, render list " << s.render_list_length << ")\n";
    return 0;
  }
  const std::string dir = args.require("--out-dir");
  std::filesystem::create_directories(dir);
  const int every = std::max(1, args.get_int("--every", 1));
  for (std::size_t i = 0; i < trace.size(); i += static_cast<std::size_t>(every)) {
    renderer->render(trace[i].camera, image);
    char name[64];
    std::snprintf(name, sizeof name, "/frame_%05zu.png", i);
    catgs::write_png(image, dir + name);
  }
  std::cerr << "wrote " << (trace.size() + every - 1) / every << " frames to " << dir << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "catgs-render: " << e.what() << "\n" << kUsage;
    return 1;
  }
}
