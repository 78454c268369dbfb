#include "bench/variants.h"

#include <algorithm>
#include <stdexcept>

#include "speculation/settings.h"

namespace catgs::bench {

namespace {

// The paper's ablations (Tables 1 and 3) and the supplementary's window table, as settings.
struct Preset {
  const char* name;
  const char* settings;
};
constexpr Preset kPresets[] = {{"catgs-nocache", "cache=off"}, {"catgs-nosplit", "split=off"}};
const std::string kWindowPreset = "catgs-w";  // catgs-wN = catgs{window=N}
// exact with occlusion culling from the last frame (RenderOptions::occlusion_culling, issue 72).
const std::string kOcclusionVariant = "exact-occlusion";

std::invalid_argument bad_variant(const std::string& text, const std::string& why) {
  return std::invalid_argument("pipeline variant '" + text + "': " + why);
}

bool all_digits(const std::string& s) { return !s.empty() && s.find_first_not_of("0123456789") == std::string::npos; }

// The pipeline and the preset settings of a name without braces; false for an unknown name.
bool expand_name(const std::string& name, Pipeline& pipeline, std::string& settings, bool& occlusion) {
  settings.clear();
  occlusion = name == kOcclusionVariant;
  if (name == "vanilla" || name == "exact" || name == "catgs" || occlusion) {
    pipeline = occlusion ? Pipeline::exact : parse_pipeline(name);
    return true;
  }
  pipeline = Pipeline::catgs;
  for (const Preset& preset : kPresets) {
    if (name == preset.name) {
      settings = preset.settings;
      return true;
    }
  }
  const std::string n = name.substr(std::min(name.size(), kWindowPreset.size()));
  if (name.rfind(kWindowPreset, 0) != 0 || !all_digits(n)) return false;
  settings = "window=" + n;
  return true;
}

// "name{settings}" -> name and settings; `braces` tells whether there were any.
void split_braces(const std::string& text, std::string& name, std::string& settings, bool& braces) {
  const auto open = text.find('{'), close = text.rfind('}');
  braces = open != std::string::npos || close != std::string::npos;
  if (!braces) {
    name = text;
    return;
  }
  if (open == std::string::npos || close != text.size() - 1 || close < open ||
      text.find_first_of("{}", open + 1) != close)
    throw bad_variant(text, "expected NAME or NAME{name=value,...} (one pair of braces, at the end)");
  name = text.substr(0, open);
  settings = text.substr(open + 1, close - open - 1);
}

}  // namespace

Variant parse_variant(const std::string& text) {
  Variant v;
  v.name = text;
  std::string name, braced;
  bool braces = false;
  split_braces(text, name, braced, braces);
  if (!expand_name(name, v.pipeline, v.settings, v.occlusion_culling))
    throw bad_variant(text, "unknown name '" + name + "'\n" + variant_syntax());
  if (braces && v.pipeline != Pipeline::catgs)
    throw bad_variant(text, std::string(pipeline_name(v.pipeline)) + " takes no settings (catgs only)");
  if (!braced.empty()) v.settings += (v.settings.empty() ? "" : ",") + braced;
  try {
    apply_speculation_settings(v.speculation, v.settings);
  } catch (const std::invalid_argument& e) {
    throw bad_variant(text, e.what());
  }
  return v;
}

std::vector<Variant> parse_variants(const std::string& list) {
  std::vector<Variant> variants;
  std::string item;
  int depth = 0;
  auto flush = [&] {
    if (item.empty()) throw std::invalid_argument("--pipeline '" + list + "': empty variant\n" + variant_syntax());
    variants.push_back(parse_variant(item));
    item.clear();
  };
  for (const char c : list) {
    depth += c == '{' ? 1 : (c == '}' ? -1 : 0);
    if (c == ',' && depth <= 0) {
      flush();
      depth = 0;
    } else {
      item += c;
    }
  }
  flush();
  return variants;
}

std::string variant_syntax() {
  std::string out =
      "pipeline variants (--pipeline V[,V...]; commas inside braces belong to the braces):\n"
      "  vanilla | exact | catgs[{SETTINGS}]   SETTINGS: name=value[,name=value...], applied in order\n"
      "  exact-occlusion                     exact, culling entries behind the last frame's opaque pixels\n"
      "  presets (the paper's ablations), which take {SETTINGS} after them too:\n";
  for (const Preset& preset : kPresets)
    out += "    " + std::string(preset.name) + " = catgs{" + preset.settings + "}\n";
  out += "    " + kWindowPreset + "N      = catgs{window=N}\n";
  out +=
      "  e.g. --pipeline 'exact,catgs{window=2,backoff=0},catgs-w2{backoff=0}' (quoted: a shell\n"
      "  expands braces with commas); the table and the JSON name each variant as written.\n"
      "  SETTINGS (catgs only):\n";
  return out + speculation_settings_usage();
}

}  // namespace catgs::bench
