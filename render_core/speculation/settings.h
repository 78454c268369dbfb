// SpeculationParams by name, for command lines (catgs-bench variants, catgs-server
// --speculation): a comma-separated list of name=value, e.g. "window=2,backoff=0,cache=off".
// Every name is a field of SpeculationParams (speculation_params.h); the table below is the one
// place that maps them.
#pragma once

#include <string>
#include <vector>

#include "speculation/speculation_params.h"

namespace catgs {

struct SpeculationSetting {
  const char* name;                                                    // as written on a command line
  const char* help;                                                    // the field it sets, its unit and its range
  void (*apply)(SpeculationParams& params, const std::string& value);  // throws on a bad value
  std::string (*show)(const SpeculationParams& params);                // the value, as written
};

// The table, in the order SpeculationParams lists the fields.
const std::vector<SpeculationSetting>& speculation_settings();

// Applies "name=value[,name=value...]" to `params` in order, then validate()s the result. An
// empty list changes nothing. Values: integers, decimals, or on/off for switches. Throws
// std::invalid_argument naming the unknown name, the malformed item or the bad value.
void apply_speculation_settings(SpeculationParams& params, const std::string& list);

// One line per setting: "  name  help (default: value)", for usage texts.
std::string speculation_settings_usage();

}  // namespace catgs
