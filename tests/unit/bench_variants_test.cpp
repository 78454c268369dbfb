// catgs-bench's --pipeline parser (tools/bench/variants.h): presets expand to settings, braces
// combine with them, commas inside braces stay there, and anything unknown is refused by name.
#include <string>

#include <gtest/gtest.h>

#include "bench/variants.h"

namespace catgs::bench {
namespace {

// The std::invalid_argument message parse_variants(list) throws ("" when it does not throw).
std::string error_of(const std::string& list) {
  try {
    parse_variants(list);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST(BenchVariants, PipelineNamesTakeTheDefaults) {
  const SpeculationParams defaults;
  for (const auto& [name, pipeline] : {std::pair{"vanilla", Pipeline::vanilla}, std::pair{"exact", Pipeline::exact},
                                       std::pair{"catgs", Pipeline::catgs}}) {
    const Variant v = parse_variant(name);
    EXPECT_EQ(v.name, name);
    EXPECT_EQ(v.pipeline, pipeline);
    EXPECT_EQ(v.settings, "");
    EXPECT_EQ(v.speculation.initial_window, defaults.initial_window);
    EXPECT_TRUE(v.speculation.frustum_and_sort_cache);
  }
}

TEST(BenchVariants, PresetsExpandToTheirSettings) {
  const SpeculationParams defaults;
  const Variant nocache = parse_variant("catgs-nocache");
  EXPECT_EQ(nocache.name, "catgs-nocache");
  EXPECT_EQ(nocache.pipeline, Pipeline::catgs);
  EXPECT_EQ(nocache.settings, "cache=off");
  EXPECT_FALSE(nocache.speculation.frustum_and_sort_cache);
  EXPECT_TRUE(nocache.speculation.task_splitting);

  const Variant nosplit = parse_variant("catgs-nosplit");
  EXPECT_EQ(nosplit.settings, "split=off");
  EXPECT_FALSE(nosplit.speculation.task_splitting);
  EXPECT_TRUE(nosplit.speculation.frustum_and_sort_cache);

  for (int w : {0, 2, 8, 16, 32}) {
    const Variant v = parse_variant("catgs-w" + std::to_string(w));
    EXPECT_EQ(v.name, "catgs-w" + std::to_string(w));
    EXPECT_EQ(v.settings, "window=" + std::to_string(w));
    EXPECT_EQ(v.speculation.initial_window, w);
    EXPECT_EQ(v.speculation.backoff.frames, defaults.backoff.frames);
  }
}

TEST(BenchVariants, BracesSetAndCombineWithPresets) {
  const Variant v = parse_variant("catgs{window=2,backoff=0}");
  EXPECT_EQ(v.name, "catgs{window=2,backoff=0}");
  EXPECT_EQ(v.pipeline, Pipeline::catgs);
  EXPECT_EQ(v.speculation.initial_window, 2);
  EXPECT_EQ(v.speculation.backoff.frames, 0);

  const Variant w = parse_variant("catgs-w2{backoff=0,motion_margin=0.2}");
  EXPECT_EQ(w.settings, "window=2,backoff=0,motion_margin=0.2");
  EXPECT_EQ(w.speculation.initial_window, 2);
  EXPECT_EQ(w.speculation.backoff.frames, 0);
  EXPECT_FLOAT_EQ(w.speculation.trail.motion_margin, 0.2f);

  const Variant n = parse_variant("catgs-nocache{split=off}");
  EXPECT_FALSE(n.speculation.frustum_and_sort_cache);
  EXPECT_FALSE(n.speculation.task_splitting);

  EXPECT_EQ(parse_variant("catgs-w2{window=8}").speculation.initial_window, 8);  // in order
  EXPECT_EQ(parse_variant("catgs{}").settings, "");
}

TEST(BenchVariants, CommasInsideBracesBelongToTheBraces) {
  const auto variants = parse_variants("exact,catgs{window=2,backoff=0},catgs-nocache,catgs-w8{split=off,fit_ms=30}");
  ASSERT_EQ(variants.size(), 4u);
  EXPECT_EQ(variants[0].name, "exact");
  EXPECT_EQ(variants[1].name, "catgs{window=2,backoff=0}");
  EXPECT_EQ(variants[1].speculation.backoff.frames, 0);
  EXPECT_EQ(variants[2].name, "catgs-nocache");
  EXPECT_EQ(variants[3].name, "catgs-w8{split=off,fit_ms=30}");
  EXPECT_DOUBLE_EQ(variants[3].speculation.predictor.fit_window_s, 0.03);
  EXPECT_EQ(parse_variants("vanilla").size(), 1u);
}

TEST(BenchVariants, UnknownNamesAreRefusedWithTheSyntax) {
  // The deleted variants among them: none may be dropped or half-read.
  for (const std::string name : {"catgs-w2-b0", "exact-warp", "catgs-nocull", "catgs-p50", "catgs-q0", "catgs-m10",
                                 "catgs-a2", "catgs-f2", "catgs-b0", "catgs-s1024", "catgs-tsort", "exact-dsort",
                                 "catgs-w", "catgs-wx", "catgs-w-2", "Catgs", "catgs ", "fast"}) {
    const std::string message = error_of("exact," + name);
    EXPECT_TRUE(contains(message, "'" + name + "'")) << name << ": " << message;
    EXPECT_TRUE(contains(message, "catgs-wN")) << name << ": " << message;       // the syntax
    EXPECT_TRUE(contains(message, "motion_margin")) << name << ": " << message;  // the settings
  }
}

TEST(BenchVariants, BadSettingsAreRefusedByName) {
  EXPECT_TRUE(contains(error_of("catgs{window=99}"), "window")) << error_of("catgs{window=99}");
  EXPECT_TRUE(contains(error_of("catgs{bogus=1}"), "bogus"));
  EXPECT_TRUE(contains(error_of("catgs{window}"), "window"));
  EXPECT_TRUE(contains(error_of("catgs{cache=maybe}"), "cache=maybe"));
  EXPECT_TRUE(contains(error_of("catgs-w40"), "catgs-w40"));  // the preset's window validated too
  const std::string exact = error_of("exact{window=2}");
  EXPECT_TRUE(contains(exact, "exact{window=2}") && contains(exact, "no settings")) << exact;
  EXPECT_TRUE(contains(error_of("vanilla{}"), "vanilla{}"));
}

TEST(BenchVariants, MalformedListsAreRefused) {
  for (const std::string list : {"", "exact,", ",exact", "exact,,catgs", "catgs{window=2", "catgs{window=2}}",
                                 "catgs{window=2}x", "catgs{{window=2}}", "catgs}window=2{", "catgswindow=2}"}) {
    EXPECT_NE(error_of(list), "") << "'" << list << "' was accepted";
  }
  EXPECT_TRUE(contains(error_of("exact,catgs{window=2"), "catgs{window=2"));
}

TEST(BenchVariants, TheSyntaxListsPresetsAndEverySetting) {
  const std::string syntax = variant_syntax();
  for (const char* part : {"catgs-nocache = catgs{cache=off}", "catgs-nosplit = catgs{split=off}", "catgs-wN", "window",
                           "backoff", "split", "cache", "fit_ms", "accel_ms", "key_colour"})
    EXPECT_TRUE(contains(syntax, part)) << part;
}

// Issue 36's key-frame colours are on by default; key_colour=off is the paper's SH at each pose.
TEST(BenchVariants, KeyColourSetting) {
  EXPECT_TRUE(parse_variant("catgs").speculation.subframe_key_colour);
  const Variant v = parse_variant("catgs-w2{key_colour=off}");
  EXPECT_EQ(v.settings, "window=2,key_colour=off");
  EXPECT_FALSE(v.speculation.subframe_key_colour);
  EXPECT_TRUE(contains(error_of("catgs{key_colour=maybe}"), "key_colour"));
}

}  // namespace
}  // namespace catgs::bench
