#include "speculation/settings.h"

#include <cmath>
#include <cstdlib>
#include <sstream>
#include <stdexcept>

namespace catgs {

namespace {

double parse_number(const std::string& value) {
  char* end = nullptr;
  const double v = std::strtod(value.c_str(), &end);
  if (value.empty() || end != value.c_str() + value.size() || !std::isfinite(v))
    throw std::invalid_argument("not a finite number");
  return v;
}

int parse_int(const std::string& value) {
  const double v = parse_number(value);
  if (!(v >= -1e9 && v <= 1e9) || v != std::floor(v)) throw std::invalid_argument("not an integer in range");
  return static_cast<int>(v);
}

std::string number(double v) {
  std::ostringstream out;
  out << v;
  return out.str();
}

std::string onoff(bool on) { return on ? "on" : "off"; }

bool parse_switch(const std::string& value) {
  if (value == "on" || value == "1" || value == "true") return true;
  if (value == "off" || value == "0" || value == "false") return false;
  throw std::invalid_argument("not on or off");
}

}  // namespace

const std::vector<SpeculationSetting>& speculation_settings() {
  using P = SpeculationParams;
  using V = const std::string&;
  static const std::vector<SpeculationSetting> table = {
      {"window", "W_initial, sub-frames after a key frame (0..32; 0: no speculation)",
       [](P& p, V v) { p.initial_window = parse_int(v); }, [](const P& p) { return std::to_string(p.initial_window); }},
      {"depth", "d, world units: only Gaussians deeper than this set the motion M",
       [](P& p, V v) { p.depth_threshold = static_cast<float>(parse_number(v)); },
       [](const P& p) { return number(p.depth_threshold); }},
      {"tile", "l, pixels: the motion at which the window starts to shrink",
       [](P& p, V v) { p.tile_size = static_cast<float>(parse_number(v)); },
       [](const P& p) { return number(p.tile_size); }},
      {"fps", "F_target: the predicted path is sampled at k / F_target (0: the poses' measured rate)",
       [](P& p, V v) { p.target_fps = parse_number(v); }, [](const P& p) { return number(p.target_fps); }},
      {"cost", "on/off: windows open only as wide as measured frame costs say they repay",
       [](P& p, V v) { p.cost_model = parse_switch(v); }, [](const P& p) { return onoff(p.cost_model); }},
      {"cache", "on/off: the frustum and sort caches (off: every frame a key frame)",
       [](P& p, V v) { p.frustum_and_sort_cache = parse_switch(v); },
       [](const P& p) { return onoff(p.frustum_and_sort_cache); }},
      {"split", "on/off: load-aware task splitting", [](P& p, V v) { p.task_splitting = parse_switch(v); },
       [](const P& p) { return onoff(p.task_splitting); }},
      {"key_colour",
       "on/off: sub-frames keep their key frame's colours (off: the SH at each sub-frame's pose, the paper's)",
       [](P& p, V v) { p.subframe_key_colour = parse_switch(v); },
       [](const P& p) { return onoff(p.subframe_key_colour); }},
      {"slack", "trails' level scaled by 1 + slack",
       [](P& p, V v) { p.trail.slack = static_cast<float>(parse_number(v)); },
       [](const P& p) { return number(p.trail.slack); }},
      {"margin_px", "trails widened by this many pixels",
       [](P& p, V v) { p.trail.margin_px = static_cast<float>(parse_number(v)); },
       [](const P& p) { return number(p.trail.margin_px); }},
      {"motion_margin", "trails widened by this fraction of the Gaussian's screen motion",
       [](P& p, V v) { p.trail.motion_margin = static_cast<float>(parse_number(v)); },
       [](const P& p) { return number(p.trail.motion_margin); }},
      {"backoff", "frames rendered in full after a group that did not repay (0: no backoff)",
       [](P& p, V v) { p.backoff.frames = parse_int(v); }, [](const P& p) { return std::to_string(p.backoff.frames); }},
      {"min_served", "sub-frames a group must serve to repay its key frame",
       [](P& p, V v) { p.backoff.min_served = parse_int(v); },
       [](const P& p) { return std::to_string(p.backoff.min_served); }},
      {"min_slice", "task splitting's shortest slice, render-list entries",
       [](P& p, V v) { p.min_slice_entries = parse_int(v); },
       [](const P& p) { return std::to_string(p.min_slice_entries); }},
      {"fit_ms", "the motion predictor's velocity fit window, ms",
       [](P& p, V v) { p.predictor.fit_window_s = parse_number(v) / 1000.0; },
       [](const P& p) { return number(p.predictor.fit_window_s * 1000.0); }},
      {"accel_ms", "the motion predictor's acceleration fit window, ms (0: constant velocity)",
       [](P& p, V v) { p.predictor.acceleration_window_s = parse_number(v) / 1000.0; },
       [](const P& p) { return number(p.predictor.acceleration_window_s * 1000.0); }},
      {"early_stop", "on/off: stop a pixel when T would drop below 1e-4",
       [](P& p, V v) { p.early_termination = parse_switch(v); }, [](const P& p) { return onoff(p.early_termination); }},
  };
  return table;
}

void apply_speculation_settings(SpeculationParams& params, const std::string& list) {
  SpeculationParams p = params;
  std::stringstream items(list);
  for (std::string item; std::getline(items, item, ',');) {
    const auto eq = item.find('=');
    if (eq == std::string::npos || eq == 0)
      throw std::invalid_argument("speculation setting '" + item + "': expected name=value");
    const std::string name = item.substr(0, eq), value = item.substr(eq + 1);
    const SpeculationSetting* found = nullptr;
    for (const auto& s : speculation_settings())
      if (name == s.name) found = &s;
    if (!found)
      throw std::invalid_argument("unknown speculation setting '" + name + "'; known:\n" +
                                  speculation_settings_usage());
    try {
      found->apply(p, value);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument("speculation setting " + name + "=" + value + ": " + e.what());
    }
  }
  validate(p);
  params = p;
}

std::string speculation_settings_usage() {
  const SpeculationParams defaults;
  std::string out;
  for (const auto& s : speculation_settings()) {
    std::string name = s.name;
    name.resize(14, ' ');
    out += "  " + name + s.help + " (default: " + s.show(defaults) + ")\n";
  }
  return out;
}

}  // namespace catgs
