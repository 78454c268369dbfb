// catgs-bench's pipeline variants: what --pipeline names, parsed and validated (no CUDA here).
//
// A variant is a pipeline name, optionally followed by SpeculationParams settings in braces:
//   vanilla | exact | catgs | catgs{window=2,backoff=0}
// The settings are exactly those of apply_speculation_settings (speculation/settings.h), catgs
// only. The paper's ablations are presets that expand to settings, and take braces too:
//   catgs-nocache = catgs{cache=off}, catgs-nosplit = catgs{split=off}, catgs-wN = catgs{window=N},
//   catgs-w2{backoff=0} = catgs{window=2,backoff=0}.
// Anything else is an error (std::invalid_argument) that lists this syntax.
#pragma once

#include <string>
#include <vector>

#include "renderer/renderer.h"

namespace catgs::bench {

struct Variant {
  std::string name;  // as the user wrote it: the table's and the JSON's pipeline name
  Pipeline pipeline = Pipeline::exact;
  std::string settings;            // the settings applied, presets expanded ("window=2,backoff=0"; "" for none)
  SpeculationParams speculation;   // the defaults with `settings` applied
  bool occlusion_culling = false;  // exact-occlusion: exact with RenderOptions::occlusion_culling
};

// One variant ("catgs-w2{backoff=0}"). Throws std::invalid_argument naming the variant: an unknown
// name (with variant_syntax()), unbalanced braces, settings on vanilla or exact, or a setting
// apply_speculation_settings refuses (its message: the setting, or the list of known ones).
Variant parse_variant(const std::string& text);

// A comma-separated list of variants; commas inside braces belong to the braces. Throws as
// parse_variant, and for an empty list or an empty item.
std::vector<Variant> parse_variants(const std::string& list);

// The syntax, the presets and the settings table (speculation_settings_usage()), for usage texts
// and error messages.
std::string variant_syntax();

}  // namespace catgs::bench
