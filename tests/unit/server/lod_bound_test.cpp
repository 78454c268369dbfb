// Each frame's level-of-detail bound (issue 46, server/render/lod_bound.h): the bound scaled with
// the session's size, judged by the yardstick that chose the 2 px default (full detail rendered
// 4x larger each way and box-filtered down, as catgs-bench --aa-reference 4); the cut's predicted
// count against the cut the CPU core draws; the splat budget's ladder, its hysteresis and its
// determinism; the auto budget's sizing. On a 9-copy city of the real flowers_sh3 scene.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <vector>

#include "common/image_io.h"
#include "forward_model/chunk_bounds.h"
#include "render/lod_bound.h"
#include "renderer/renderer.h"
#include "server_options.h"
#include "small_city.h"
#include "test_data.h"

namespace {

using namespace catgs;
using namespace catgs::server;

using test::small_flowers_city;

std::unique_ptr<Renderer> exact_cpu(std::shared_ptr<const GaussianModel> m, float tau) {
  RenderOptions o;
  o.pipeline = Pipeline::exact;
  o.lod_error_px = tau;
  return make_renderer("cpu", std::move(m), o);
}

TEST(LodBound, ScalesWithTheShorterSideBelowTheReference) {
  EXPECT_FLOAT_EQ(size_scaled_lod_bound(2.0f, 1280, 720, 720), 2.0f);
  EXPECT_FLOAT_EQ(size_scaled_lod_bound(2.0f, 1920, 1080, 720), 2.0f);  // never coarser than given
  EXPECT_FLOAT_EQ(size_scaled_lod_bound(2.0f, 720, 1280, 720), 2.0f);   // portrait: the shorter side
  EXPECT_FLOAT_EQ(size_scaled_lod_bound(2.0f, 320, 180, 720), 0.5f);
  EXPECT_FLOAT_EQ(size_scaled_lod_bound(2.0f, 640, 360, 720), 1.0f);
  EXPECT_EQ(size_scaled_lod_bound(0.0f, 320, 180, 720), 0.0f);  // full detail stays full
  ServerOptions defaults;
  EXPECT_EQ(defaults.store.lod, "write");                      // on by default (issue 46)
  EXPECT_FLOAT_EQ(defaults.session.frame.lod.bound_px, 4.0f);  // 2 before the fitted merges (issue 72)
  EXPECT_TRUE(defaults.session.frame.lod.auto_budget);
}

// The yardstick (issue 46): at the server's default bound scaled to the session's size, the cut
// scores within 0.5 dB of full detail's own score against the supersampled render, mean over the
// fly-over's views, and draws fewer Gaussians, at 320x180 and 640x360. (The unscaled 2 px at
// 320x180 lost 3.4 dB here: docs/history/level_of_detail.md.)
TEST(LodBound, DefaultBoundAtEachSizeWithinHalfADbOfFullDetailAgainstSupersampled) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const test::SmallCity& c = small_flowers_city();
  const float bound = ServerOptions{}.session.frame.lod.bound_px;
  constexpr int kFactor = 4;
  for (const int scale : {1, 2}) {
    double full_db = 0, cut_db = 0;
    std::size_t full_visible = 0, cut_visible = 0, n = 0;
    Image hi, f, l;
    for (std::size_t k = 0; k < c.views.size(); k += 2 * scale, ++n) {
      const Camera v = c.views[k].rescaled(c.views[k].width * scale, c.views[k].height * scale);
      const float tau = size_scaled_lod_bound(bound, v.width, v.height, LodSettings{}.reference_lines);
      auto full = exact_cpu(c.full, 0.0f);
      auto cut = exact_cpu(c.lod, tau);
      full->render(v.rescaled(v.width * kFactor, v.height * kFactor), hi);
      const Image reference = box_downsample(hi, kFactor);
      full->render(v, f);
      full_visible += full->last_stats().visible;
      cut->render(v, l);
      cut_visible += cut->last_stats().visible;
      const double fd = psnr_rgba8(f, reference), cd = psnr_rgba8(l, reference);
      std::printf("%dx%d view %zu: full detail %.2f dB, cut at %.2f px %.2f dB against the supersampled render\n",
                  v.width, v.height, k, fd, tau, cd);
      full_db += fd;
      cut_db += cd;
    }
    full_db /= static_cast<double>(n);
    cut_db /= static_cast<double>(n);
    EXPECT_GE(cut_db, full_db - 0.5) << "scale " << scale << ", mean over " << n << " views";
    EXPECT_LT(cut_visible, full_visible) << "scale " << scale;
  }
}

// The predicted count: at most the cut's chunks with no frustum at all (every drawn chunk, as
// fm::lod_chunk_drawn says), all of them for a view that holds the whole city, and at least the
// Gaussians the CPU core's culling lets through at that bound.
TEST(LodBound, PredictedCountBracketsTheCutTheCoreDraws) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const test::SmallCity& c = small_flowers_city();
  const CutCounter counter(*c.lod);
  ASSERT_TRUE(counter.has_lod());
  for (const float tau : {0.5f, 2.0f, 8.0f}) {
    for (std::size_t k = 0; k < c.views.size(); ++k) {
      const Camera& v = c.views[k];
      const fm::LodCut cut = fm::lod_cut(
          c.lod->lod, fm::View{v.R, v.t, v.fx, v.fy, v.cx, v.cy, v.width, v.height, v.near_plane, v.far_plane, {}},
          tau);
      std::uint64_t drawn = 0;
      for (std::size_t ch = 0; ch < c.lod->lod.size(); ++ch) drawn += cut.drawn(ch) ? fm::kChunkSize : 0;
      const std::uint64_t predicted = counter.splats(v, tau);
      auto r = exact_cpu(c.lod, tau);
      Image img;
      r->render(v, img);
      EXPECT_LE(predicted, drawn) << "tau " << tau << " view " << k;
      EXPECT_GE(predicted, r->last_stats().visible) << "tau " << tau << " view " << k;
      if (k == 0) {
        EXPECT_EQ(predicted, drawn) << "the first view, outside the city, sees all of it";
      }
    }
  }
  // A view looking away from the city predicts nothing.
  Camera away = c.views.front();
  const glm::vec3 eye = away.position();
  away.R = glm::mat3(-1.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 0.0f, -1.0f) * away.R;  // turned around
  away.t = -(away.R * eye);
  EXPECT_LT(counter.splats(away, 2.0f), counter.splats(c.views.front(), 2.0f) / 4);
}

// Whether a node's box lies wholly beyond one plane of the view frustum widened by 15% on each
// side, worked out from its eight corners (the oracle for CutCounter's centre-and-extent test).
bool box_outside_by_corners(const fm::LodNode& n, const Camera& cam) {
  const float w = static_cast<float>(cam.width), h = static_cast<float>(cam.height);
  const float left = cam.cx + 0.15f * w, right = cam.cx - 1.15f * w;
  const float top = cam.cy + 0.15f * h, bottom = cam.cy - 1.15f * h;
  int out[5] = {0, 0, 0, 0, 0};
  for (int k = 0; k < 8; ++k) {
    const glm::vec3 corner((k & 1) ? n.hi[0] : n.lo[0], (k & 2) ? n.hi[1] : n.lo[1], (k & 4) ? n.hi[2] : n.lo[2]);
    const glm::vec3 p = cam.R * corner + cam.t;
    out[0] += p.z < cam.near_plane;
    out[1] += cam.fx * p.x + left * p.z < 0.0f;
    out[2] += cam.fx * p.x + right * p.z > 0.0f;
    out[3] += cam.fy * p.y + top * p.z < 0.0f;
    out[4] += cam.fy * p.y + bottom * p.z > 0.0f;
  }
  for (int plane : out)
    if (plane == 8) return true;
  return false;
}

// The count, chunk by chunk from the cut the CPU core draws (fm::lod_cut) and each drawn chunk's
// own box by its corners (a box beyond a plane holds only boxes beyond it, so no ancestor need be
// tested); and the one walk that counts two bounds gives each bound's count.
TEST(LodBound, CountIsTheCutsChunksInTheWidenedFrustumAtEitherOfTwoBounds) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const test::SmallCity& c = small_flowers_city();
  const CutCounter counter(*c.lod);
  const auto oracle = [&c](const Camera& v, float tau) {
    const fm::LodCut cut = fm::lod_cut(
        c.lod->lod, fm::View{v.R, v.t, v.fx, v.fy, v.cx, v.cy, v.width, v.height, v.near_plane, v.far_plane, {}}, tau);
    std::uint64_t in_view = 0, drawn = 0;
    for (std::size_t ch = 0; ch < c.lod->lod.size(); ++ch) {
      drawn += cut.drawn(ch) ? fm::kChunkSize : 0;
      in_view += cut.drawn(ch) && !box_outside_by_corners(c.lod->lod[ch], v) ? fm::kChunkSize : 0;
    }
    return std::pair{in_view, drawn};
  };
  int partly_in_view = 0;
  for (const auto& [coarse, fine] : {std::pair{0.71f, 0.5f}, std::pair{2.83f, 2.0f}, std::pair{8.0f, 0.5f}}) {
    for (std::size_t k = 0; k < c.views.size(); ++k) {
      const Camera& v = c.views[k];
      const CutCounter::Counts both = counter.splats(v, coarse, fine);
      const auto [want_coarse, drawn_coarse] = oracle(v, coarse);
      const std::uint64_t want_fine = oracle(v, fine).first;
      EXPECT_EQ(both.coarse, want_coarse) << "bound " << coarse << " view " << k;
      EXPECT_EQ(both.fine, want_fine) << "bound " << fine << " view " << k;
      EXPECT_EQ(counter.splats(v, coarse), want_coarse) << "bound " << coarse << " view " << k;
      EXPECT_LT(both.coarse, both.fine) << "view " << k;
      partly_in_view += want_coarse < drawn_coarse ? 1 : 0;
    }
  }
  EXPECT_GT(partly_in_view, 0) << "some views must leave part of the city out of the frustum";
}

TEST(LodBound, BudgetStepsUpUntilTheCutFitsAndDownWithHysteresis) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const test::SmallCity& c = small_flowers_city();
  const CutCounter counter(*c.lod);
  const Camera& v = c.views[2];
  const float base = 0.5f;
  const std::uint64_t at_base = counter.splats(v, base);
  ASSERT_GT(at_base, 0u);

  LodBoundChooser none;
  EXPECT_EQ(none.choose(counter, v, base, 0), base);  // no budget: the size's bound
  LodBoundChooser roomy;
  EXPECT_EQ(roomy.choose(counter, v, base, at_base), base);  // fits: no step
  EXPECT_EQ(roomy.predicted_splats(), at_base);

  // Half the cut's count: the bound steps up until the prediction fits.
  const std::uint64_t budget = at_base / 2;
  LodBoundChooser tight;
  const float tau = tight.choose(counter, v, base, budget);
  ASSERT_GT(tight.step(), 0);
  EXPECT_FLOAT_EQ(tau, LodBoundChooser::bound_at(base, tight.step()));
  EXPECT_LE(tight.predicted_splats(), budget);
  EXPECT_EQ(tight.predicted_splats(), counter.splats(v, tau));
  EXPECT_GT(counter.splats(v, LodBoundChooser::bound_at(base, tight.step() - 1)), budget);  // the first that fits
  // The same pose again: the same bound (a still camera keeps its cut).
  for (int i = 0; i < 3; ++i) EXPECT_EQ(tight.choose(counter, v, base, budget), tau);

  // Hysteresis: a budget the finer step just fits does not step down; one with a quarter to spare does.
  const std::uint64_t finer = counter.splats(v, LodBoundChooser::bound_at(base, tight.step() - 1));
  const int step = tight.step();
  EXPECT_EQ(tight.choose(counter, v, base, finer), tau);
  EXPECT_EQ(tight.step(), step);
  EXPECT_LT(tight.choose(counter, v, base, finer * 4 / 3 + 1), tau);
  EXPECT_EQ(tight.step(), step - 1);

  // A budget nothing fits: the top of the ladder, no further.
  LodBoundChooser starved;
  EXPECT_FLOAT_EQ(starved.choose(counter, v, base, 1), LodBoundChooser::bound_at(base, LodBoundChooser::kSteps));
  EXPECT_TRUE(starved.over_budget());
  EXPECT_FALSE(tight.over_budget());
}

// --lod-max-error (issue 72): the ladder stops at the ceiling, and a cut that still passes the
// budget there says so (the door then refuses the GPU's next visitor) rather than blurring on.
TEST(LodBound, CeilingStopsTheLadderAndSaysWhenTheBudgetIsShort) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const test::SmallCity& c = small_flowers_city();
  const CutCounter counter(*c.lod);
  const Camera& v = c.views[2];
  const float base = 0.5f;
  LodBoundChooser free_ladder;
  const std::uint64_t budget = counter.splats(v, base) / 2;
  const float tau = free_ladder.choose(counter, v, base, budget);
  const int needed = free_ladder.step();
  ASSERT_GE(needed, 2) << "the test needs a budget two steps or more up the ladder";
  // A ceiling one step short of what the budget asks: the frame draws there, over its budget.
  LodBoundChooser held;
  const float capped = held.choose(counter, v, base, budget, needed - 1);
  EXPECT_FLOAT_EQ(capped, LodBoundChooser::bound_at(base, needed - 1));
  EXPECT_LT(capped, tau);
  EXPECT_TRUE(held.over_budget());
  EXPECT_GT(held.predicted_splats(), budget);
  // A ceiling at or above the step needed: as without one.
  LodBoundChooser roomy;
  EXPECT_FLOAT_EQ(roomy.choose(counter, v, base, budget, needed), tau);
  EXPECT_FALSE(roomy.over_budget());
  // A chooser that stood higher (a ceiling lowered since) comes down to it at once.
  EXPECT_FLOAT_EQ(free_ladder.choose(counter, v, base, budget, 0), base);
  EXPECT_TRUE(free_ladder.over_budget());
  // Over budget in a row: the streak the door reads; a frame within the budget ends it.
  LodBoundChooser streak;
  for (int k = 1; k <= 3; ++k) {
    streak.choose(counter, v, base, budget, needed - 1);
    EXPECT_EQ(streak.over_budget_streak(), k);
  }
  streak.choose(counter, v, base, budget, needed);
  EXPECT_EQ(streak.over_budget_streak(), 0);
  streak.choose(counter, v, base, budget, needed - 1);
  EXPECT_EQ(streak.over_budget_streak(), 1);
  streak.choose(counter, v, base, 0, needed - 1);  // no budget
  EXPECT_EQ(streak.over_budget_streak(), 0);
  // The ceiling in steps: 2 px to 2.83 px is one x sqrt(2) step, 4 px two, 0 (off) the ladder's top.
  EXPECT_EQ(lod_max_steps(2.0f, 2.83f), 1);
  EXPECT_EQ(lod_max_steps(2.0f, 2.0f * std::sqrt(2.0f)), 1);
  EXPECT_EQ(lod_max_steps(2.0f, 4.0f), 2);
  EXPECT_EQ(lod_max_steps(2.0f, 2.5f), 0);
  EXPECT_EQ(lod_max_steps(2.0f, 1.0f), 0);
  EXPECT_EQ(lod_max_steps(2.0f, 0.0f), LodBoundChooser::kSteps);
  EXPECT_EQ(lod_max_steps(2.0f, 1000.0f), LodBoundChooser::kSteps);
  LodSettings lod;
  lod.bound_px = 2.0f;
  lod.max_bound_px = 4.0f;
  EXPECT_EQ(lod.max_steps(), 2);
  EXPECT_FLOAT_EQ(lod.coarsest_bound_px(), 4.0f);
}

TEST(LodBound, AutoBudgetSharesTheGpusThroughputInPowersOfSqrt2) {
  EXPECT_EQ(auto_splat_budget(0.0, 1), 0u);  // not known yet: no budget
  const std::uint64_t one = auto_splat_budget(2.0e6, 1, 0.8), four = auto_splat_budget(2.0e6, 4, 0.8);
  // 2 M Gaussians a ms x 16.7 ms x a share of 0.8 = 26.7 M, down to a power of sqrt(2).
  EXPECT_LE(one, 26'666'667u);
  EXPECT_GT(static_cast<double>(one), 26'666'667.0 / std::sqrt(2.0));
  EXPECT_LE(four, one / 4 + 1);
  EXPECT_GT(static_cast<double>(four), static_cast<double>(one) / 4.0 / std::sqrt(2.0));
  // Rounded: 10% more throughput moves the budget by one step or not at all.
  const double steps =
      std::log2(static_cast<double>(auto_splat_budget(2.2e6, 1, 0.8)) / static_cast<double>(one)) * 2.0;
  EXPECT_TRUE(std::abs(steps) < 1e-6 || std::abs(steps - 1.0) < 1e-6) << steps;
  // A slow GPU shared by many (or one slow first frame) asks no frame for fewer than the floor.
  EXPECT_EQ(auto_splat_budget(2.8e3, 4), kAutoBudgetFloor);
  EXPECT_GT(auto_splat_budget(2.0e6, 16, 0.8), kAutoBudgetFloor);
  // Half the share, half the budget (to the power of sqrt(2) below).
  const std::uint64_t half = auto_splat_budget(2.0e6, 1, 0.4);
  EXPECT_LE(half, 13'333'334u);
  EXPECT_GT(static_cast<double>(half), 13'333'334.0 / std::sqrt(2.0));
}

TEST(LodBound, SplatBudgetOption) {
  const char* a1[] = {"catgs-server", "--splat-budget", "2000000"};
  ServerOptions o1;
  ASSERT_TRUE(parse_server_options(3, const_cast<char**>(a1), o1));
  EXPECT_EQ(o1.session.frame.lod.splat_budget, 2000000u);
  const char* a2[] = {"catgs-server", "--splat-budget", "off"};
  ServerOptions o2;
  ASSERT_TRUE(parse_server_options(3, const_cast<char**>(a2), o2));
  EXPECT_EQ(o2.session.frame.lod.splat_budget, 0u);
  EXPECT_FALSE(o2.session.frame.lod.auto_budget);
  const char* a3[] = {"catgs-server", "--splat-budget", "lots"};
  ServerOptions o3;
  EXPECT_THROW((void)parse_server_options(3, const_cast<char**>(a3), o3), std::invalid_argument);
  // --lod-max-error: by default the default bound (the budget never coarsens the default picture,
  // issue 72), a value, or off (the ladder's top).
  EXPECT_EQ(ServerOptions{}.session.frame.lod.max_bound_px, ServerOptions{}.session.frame.lod.bound_px);
  EXPECT_EQ(lod_max_steps(ServerOptions{}.session.frame.lod.bound_px, ServerOptions{}.session.frame.lod.max_bound_px),
            0);
  const char* a4[] = {"catgs-server", "--lod-max-error", "5.66"};
  ServerOptions o4;
  ASSERT_TRUE(parse_server_options(3, const_cast<char**>(a4), o4));
  EXPECT_EQ(o4.session.frame.lod.max_bound_px, 5.66f);
  const char* a5[] = {"catgs-server", "--lod-max-error", "off"};
  ServerOptions o5;
  ASSERT_TRUE(parse_server_options(3, const_cast<char**>(a5), o5));
  EXPECT_EQ(o5.session.frame.lod.max_bound_px, 0.0f);
  const char* a6[] = {"catgs-server", "--lod-max-error", "-1"};
  ServerOptions o6;
  EXPECT_THROW((void)parse_server_options(3, const_cast<char**>(a6), o6), std::invalid_argument);
  // --splat-budget-share: 0.4 by default, in (0, 1].
  EXPECT_EQ(ServerOptions{}.session.frame.lod.budget_share, 0.4);
  const char* a7[] = {"catgs-server", "--splat-budget-share", "0.5"};
  ServerOptions o7;
  ASSERT_TRUE(parse_server_options(3, const_cast<char**>(a7), o7));
  EXPECT_EQ(o7.session.frame.lod.budget_share, 0.5);
  const char* a8[] = {"catgs-server", "--splat-budget-share", "1.5"};
  ServerOptions o8;
  EXPECT_THROW((void)parse_server_options(3, const_cast<char**>(a8), o8), std::invalid_argument);
}

}  // namespace

// Issue 93: one declaration per option. Settings built without options (as tests and the fuzz
// target build them) are what a server started without options runs: parsing no arguments
// changes no option's value (but the two resolved at parse time), --help shows each option's
// default from its field, and that text given back as the option changes nothing.
TEST(ServerDefaults, ASessionWithoutOptionsRunsTheServersDefaults) {
  const char* none[] = {"catgs-server"};
  ServerOptions parsed;
  ASSERT_TRUE(parse_server_options(1, const_cast<char**>(none), parsed));
  ServerOptions plain;
  plain.session = SessionSettings{};
  const std::map<std::string, std::string> want = option_values(parsed);
  const std::map<std::string, std::string> got = option_values(plain);
  ASSERT_GT(want.size(), 50u);  // the options with a value to show
  for (const auto& [name, value] : want) {
    if (name == "--threads" || name == "--max-pixels-in-flight") continue;  // resolved at parse time
    EXPECT_EQ(got.at(name), value) << name;
  }
  const std::string usage = server_usage();
  for (const auto& [name, value] : option_values(ServerOptions{})) {
    // --help says the default from the same field.
    const std::size_t at = usage.find("\n  " + name + " ");  // an option line, not a mention
    ASSERT_NE(at, std::string::npos) << name;
    const std::size_t next = usage.find("\n  --", at + 1);
    std::string entry = usage.substr(at + 1, next - at - 1);
    for (char& c : entry)
      if (c == '\n') c = ' ';
    std::string flat;  // the wrapped lines' indentation folded to one space
    for (char c : entry)
      if (!(c == ' ' && !flat.empty() && flat.back() == ' ')) flat += c;
    EXPECT_NE(flat.find("(default " + value + ")"), std::string::npos) << name << ": " << flat;
    // The default, given back, is parsed to itself.
    const char* again[] = {"catgs-server", name.c_str(), value.c_str()};
    ServerOptions o;
    ASSERT_TRUE(parse_server_options(3, const_cast<char**>(again), o)) << name;
    EXPECT_EQ(option_values(o), option_values(parsed)) << name << " " << value;
  }
}

// The option given as --name=value is the same option; one given twice, the last wins; an
// unknown one, a value missing or out of range is refused with the option's name.
TEST(ServerDefaults, OptionsParseAsTheirTableSays) {
  const char* eq[] = {"catgs-server", "--lod-error=2.5", "--port", "9000", "--port", "9001"};
  ServerOptions o;
  ASSERT_TRUE(parse_server_options(6, const_cast<char**>(eq), o));
  EXPECT_EQ(o.session.frame.lod.bound_px, 2.5f);
  EXPECT_EQ(o.transport.port, 9001);
  const std::vector<std::vector<const char*>> bad = {{"catgs-server", "--nope", "1"},
                                                     {"catgs-server", "--port"},
                                                     {"catgs-server", "--port", "70000"},
                                                     {"catgs-server", "--occlusion-cull", "maybe"},
                                                     {"catgs-server", "scene.ply"}};
  for (const auto& argv : bad) {
    ServerOptions b;
    try {
      (void)parse_server_options(static_cast<int>(argv.size()), const_cast<char**>(argv.data()), b);
      ADD_FAILURE() << argv.back() << " accepted";
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what(), arg = argv[1];
      EXPECT_NE(what.find(arg), std::string::npos) << what;
    }
  }
  // --socket-send-buffer is the transport's first size and the session's most: one option, both.
  const char* sndbuf[] = {"catgs-server", "--socket-send-buffer", "65536"};
  ServerOptions s;
  ASSERT_TRUE(parse_server_options(3, const_cast<char**>(sndbuf), s));
  EXPECT_EQ(s.transport.socket_send_buffer, 65536);
  EXPECT_EQ(s.session.frame.socket_send_buffer, 65536);
  EXPECT_EQ(ServerOptions{}.transport.socket_send_buffer, SessionSettings{}.frame.socket_send_buffer);
}
