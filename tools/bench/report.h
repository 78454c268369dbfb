// catgs-bench's report: the table on stdout and the JSON (scripts/bench_tables.py and earlier
// results read both: their columns and keys stay as they are).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/timing_loop.h"

namespace catgs::bench {

// What the run measured on: the report's header and the JSON's top-level fields.
struct BenchContext {
  std::string gpu;  // device_description(), or the CPU reference's thread count
  bool on_gpu = false;
  std::string scene;
  std::size_t gaussians = 0;
  int sh_degree = 0;
  std::size_t scene_device_bytes = 0;  // CUDA: the DeviceScene's bytes
  std::string trace;                   // --trace as given
  int width = 0, height = 0, frames = 0, warmup = 0;
  double pose_rate_hz = 120.0;  // --pose-rate: the frames' clock
  // Level of detail (forward_model/lod.h): the scene has it (built by --lod or read by
  // --lod-file), the bound every variant drew with, the build time (--lod) and chunks per level.
  bool lod = false;
  float lod_error_px = 0.0f;  // the first bound (--lod-error; the variants' names carry each)
  double lod_build_s = 0.0;
  std::vector<std::size_t> lod_levels;
};

// Prints the table (a row per variant; catgs: key / sub-frames, groups by W, stages, quality)
// and the FPS ratios, and returns the same as JSON.
nlohmann::json report(const BenchContext& context, const std::vector<PipelineResult>& results);

// Writes `json` to `path`. Throws std::runtime_error naming the path when the write fails.
void write_json(const nlohmann::json& json, const std::string& path);

}  // namespace catgs::bench
