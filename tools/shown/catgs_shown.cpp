// catgs-shown: the shown-picture measure (issue 91). Scores, per display refresh of a visitor
// following a real path, what the visitor's screen shows against the ideal picture of where the
// visitor is then (shown/shown_score.h), beside two pictures with no codec and no delay:
//   full detail   our renderer at the display pose, every Gaussian
//   anchor        our renderer at the display pose within a splat budget (--anchor-budget, 1.5 M:
//                 Spark 2.0's default; the finest cut of the LOD ladder whose predicted Gaussians
//                 fit it, server/render/lod_bound.h CutCounter), what a client-side renderer shows
//   shown NAME    each recorded run (catgs-loadgen --record): the newest frame visible by the
//                 refresh, re-projected by the page's rule to the display pose
// With --parts, the loss split into its parts (issue 91: which part binds, and by how much):
//   server cut    our renderer at the display pose at the server's LOD bound (the first run's
//                 shown frame's): the level of detail alone, no codec, no delay
//   no codec NAME the shown frame's pose rendered raw at its LOD bound (our renderer, not the
//                 decoded stream), re-projected as the depth warp row is (the frame's own depth
//                 grid): the delay alone over `server cut`; the depth warp row less it is the codec
// Each session of the first run is scored with the session of the same folder name in every other
// run (or a run's only session), which must have the same trace, size and offset: the display
// poses are then the same, so each refresh's ideal is rendered once for every row. A loaded run
// may hold more sessions than the first: the others are not scored.
//
//   catgs-shown --scene S.ply --run landed=/tmp/rec_a,main=/tmp/rec_b --json shown.json
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <future>
#include <iostream>
#include <map>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "common/cli_args.h"
#include "common/image_io.h"
#include "cpu/pixel_depth.h"
#include "process/scene_with_lod.h"
#include "render/lod_bound.h"
#include "scene/scene_bounds.h"
#include "proto/depth_grid_coding.h"
#include "shown/depth_warp.h"
#include "shown/page_reprojection.h"
#include "shown/shown_score.h"

using namespace catgs;
using namespace catgs::shown;

namespace {

const char* kUsage =
    "usage: catgs-shown --scene FILE --run NAME=DIR[,NAME=DIR...] [options]\n"
    "  --scene FILE          the scene the runs streamed (its level of detail as the server reads\n"
    "                        it: the LOD file in --cache-dir or beside it, else built here)\n"
    "  --cache-dir DIR       the server's --cache-dir (where its LOD file is)\n"
    "  --run NAME=DIR,...    catgs-loadgen --record folders (session_I inside), one row each\n"
    "  --renderer KIND       cpu | cuda | auto (default auto)\n"
    "  --aa N                the ideal is rendered N times larger and box-filtered (default 4)\n"
    "  --refresh-hz HZ       the display's refresh rate (default 60)\n"
    "  --warmup-s S          refreshes before S seconds are not scored (default 1)\n"
    "  --every N             score every Nth refresh (default 1)\n"
    "  --anchor-budget N     the client-side anchor's splat budget (default 1500000)\n"
    "  --json FILE           write every row's per-refresh scores and summaries\n"
    "  --png-dir DIR         write the pictures of each session's worst shown refresh\n"
    "  --plain               also score each run's newest frame as it is (no re-projection)\n"
    "  --plane-depth D       re-project with a plane D units ahead of the frame, not the page's\n"
    "  --depth-warp          also re-project each run by its frames' depth grids as a mesh\n"
    "                        (shown/depth_warp.h; frames without one: the page's plane)\n"
    "  --centre-plane        also re-project each run with the plane at the depth under the\n"
    "                        frame's centre pixel (the depth probe at full detail; not the page)\n"
    "  --parts               also the loss's parts: the server's LOD cut at the display pose, and\n"
    "                        each run's frames rendered raw (no codec) and re-projected as\n"
    "                        --depth-warp does (which it implies)\n"
    "The table: PSNR (dB) and SSIM mean and 5th percentile over the refreshes; the last column is\n"
    "the anchor's mean LOD bound (px) and a shown row's mean frame age (ms: display pose to the\n"
    "shown frame's pose).\n";

constexpr float kAnchorBase = 0.5f;  // the anchor ladder's finest bound above full detail, px

// The finest bound whose cut's predicted Gaussians fit `budget` (0 = full detail when the whole
// view fits), up the ladder of x sqrt(2) steps; the ladder's top when none does.
float anchor_bound(const server::CutCounter& counter, const Camera& camera, std::uint64_t budget) {
  if (!counter.has_lod() || counter.splats(camera, 0.0f) <= budget) return 0.0f;
  float tau = kAnchorBase;
  for (int step = 0; step < 16; ++step, tau *= 1.41421356f)
    if (counter.splats(camera, tau) <= budget) return tau;
  return tau;
}

std::vector<std::string> session_dirs(const std::string& dir) {
  std::vector<std::string> out;
  if (std::filesystem::exists(dir + "/meta.json")) return {dir};
  if (!std::filesystem::is_directory(dir)) throw std::runtime_error(dir + ": not a folder");
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.is_directory() && std::filesystem::exists(e.path() / "meta.json")) out.push_back(e.path().string());
  std::sort(out.begin(), out.end());
  if (out.empty()) throw std::runtime_error(dir + ": no recorded session (catgs-loadgen --record)");
  return out;
}

struct RunSpec {
  std::string name, dir;
};

std::vector<RunSpec> parse_runs(const std::string& text) {
  std::vector<RunSpec> runs;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ',');) {
    const auto eq = item.find('=');
    if (eq == std::string::npos || eq == 0) throw std::invalid_argument("--run wants NAME=DIR, got '" + item + "'");
    runs.push_back({item.substr(0, eq), item.substr(eq + 1)});
  }
  if (runs.empty()) throw std::invalid_argument("--run needs at least one NAME=DIR");
  return runs;
}

RenderOptions detail(float lod_error_px) {
  RenderOptions o;
  o.lod_error_px = lod_error_px;
  o.list_budget = RenderListBudget::unlimited();
  return o;
}

nlohmann::json row_json(const Row& row) {
  const Summary p = summarize(row.psnr), s = summarize(row.ssim);
  nlohmann::json j = {{"refreshes", p.count}, {"psnr_db_mean", p.mean}, {"psnr_db_p5", p.p5},  {"psnr_db_min", p.min},
                      {"ssim_mean", s.mean},  {"ssim_p5", s.p5},        {"psnr_db", row.psnr}, {"ssim", row.ssim}};
  // The anchor's LOD bound (px) or a shown row's frame age (ms), as a mean.
  if (!row.detail.empty())
    j[row.name.rfind("anchor", 0) == 0 ? "lod_bound_px_mean" : "age_ms_mean"] = summarize(row.detail).mean;
  return j;
}

void print_row(const std::string& session, const Row& row) {
  const Summary p = summarize(row.psnr), s = summarize(row.ssim);
  std::printf("%-12s %-22s %8zu %9.2f %9.2f %9.4f %9.4f %9.2f\n", session.c_str(), row.name.c_str(), p.count, p.mean,
              p.p5, s.mean, s.p5, row.detail.empty() ? 0.0 : summarize(row.detail).mean);
}

// A picture at another size than the display (adaptive quality shrank the stream): stretched to
// it as the page's CSS does, bilinearly.
Image stretched(const Image& src, int width, int height) {
  if (src.width == width && src.height == height) return src;
  Image out;
  out.width = width;
  out.height = height;
  out.rgba8.resize(static_cast<std::size_t>(width) * height * 4);
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i) {
      const auto rgb = sample_bilinear(src, (i + 0.5) * src.width / width, (j + 0.5) * src.height / height);
      std::uint8_t* o = &out.rgba8[(static_cast<std::size_t>(j) * width + i) * 4];
      for (int c = 0; c < 3; ++c) o[c] = static_cast<std::uint8_t>(std::lround(rgb[static_cast<std::size_t>(c)]));
      o[3] = 255;
    }
  return out;
}

struct Scorer {
  std::shared_ptr<const GaussianModel> model;
  std::unique_ptr<server::CutCounter> counter;
  std::unique_ptr<Renderer> ideal, view;
  int aa = 4;
  double refresh_hz = 60, warmup_s = 1;
  int every = 1;
  std::uint64_t budget = 1500000;
  std::string png_dir;
  double plane_depth = 0;  // --plane-depth: another plane than the page's (0: the page's)
  bool plain = false;      // --plain: each run's newest frame also as it is, not re-projected
  bool parts = false;      // --parts: rows "server cut" and "no codec NAME" (the header says why)
  // --centre-plane: each run also re-projected with the plane at the depth under the frame's centre
  // pixel (cpu::probe_pixel_depth at full detail: what a depth sent with each frame would give).
  bool centre = false;
  // --depth-warp: each run also re-projected by its frames' depth grids (shown/depth_warp.h).
  bool depth_warp = false;
  std::vector<fm::ChunkBounds> chunks;  // the probe's chunk culling (--centre-plane)

  // The depth under the centre pixel of frame `frame` of run `r` (0: no surface there), probed
  // once a frame.
  std::vector<std::pair<std::int64_t, double>> centre_depths;
  double centre_depth(std::size_t r, const RecordingPlayer& player, const Camera& frame_pose) {
    auto& [frame, depth] = centre_depths[r];
    if (frame != player.shown_index()) {
      frame = player.shown_index();
      const cpu::PixelDepth d =
          cpu::probe_pixel_depth(*model, frame_pose, frame_pose.width / 2.0, frame_pose.height / 2.0, &chunks);
      depth = d.hit ? d.depth : 0.0;
    }
    return depth;
  }

  // The LOD bound the shown frame of `player` was drawn at, px (Frame.lod_error_px).
  static float lod_bound_of(const RecordingPlayer& player) {
    return player.recording().frames[static_cast<std::size_t>(player.shown_index())].lod_error_px;
  }

  // One session of every run: rows full detail, anchor, then each run's shown picture (and, with
  // --plain, each run's frame as it arrived; --centre-plane, --depth-warp and --parts their rows,
  // the server's cut last).
  std::vector<Row> score(const std::vector<std::string>& names, std::vector<RecordingPlayer>& players,
                         const std::string& session) {
    const std::size_t runs = players.size();
    const std::size_t kinds = 1 + (plain ? 1 : 0) + (centre ? 1 : 0) + (depth_warp ? 1 : 0) + (parts ? 1 : 0);
    std::vector<Row> rows(2 + runs * kinds + (parts ? 1 : 0));
    centre_depths.assign(runs, {-1, 0.0});
    rows[0].name = "full detail";
    rows[1].name = "anchor " + std::to_string(budget / 1000) + " k";
    for (std::size_t r = 0; r < runs; ++r) rows[2 + r].name = "shown " + names[r];
    for (std::size_t r = 0; plain && r < runs; ++r) rows[2 + runs + r].name = "plain " + names[r];
    const std::size_t centre_row = 2 + runs * (plain ? 2 : 1);
    for (std::size_t r = 0; centre && r < runs; ++r) rows[centre_row + r].name = "centre " + names[r];
    const std::size_t warp_row = centre_row + (centre ? runs : 0);
    for (std::size_t r = 0; depth_warp && r < runs; ++r) rows[warp_row + r].name = "depth warp " + names[r];
    const std::size_t raw_row = warp_row + (depth_warp ? runs : 0), cut_row = raw_row + runs;
    for (std::size_t r = 0; parts && r < runs; ++r) rows[raw_row + r].name = "no codec " + names[r];
    if (parts) rows[cut_row].name = "server cut";
    const loadgen::SessionRecording& first = players.front().recording();
    double start_ms = 1000.0 * warmup_s;
    for (const auto& p : players) start_ms = std::max(start_ms, p.first_visible_ms());
    const double period_ms = 1000.0 / refresh_hz;
    Image hi, full, anchor;
    double worst = 1e300;
    for (double t = std::ceil(start_ms / period_ms) * period_ms; t <= 1000.0 * first.seconds; t += every * period_ms) {
      const Camera display = players.front().display_pose(t);
      ideal->render(display.rescaled(display.width * aa, display.height * aa), hi);
      const Image want = box_downsample(hi, aa);
      view->set_options(detail(0.0f));
      view->render(display, full);
      const float bound = anchor_bound(*counter, display, budget);
      rows[1].detail.push_back(bound);
      view->set_options(detail(bound));
      view->render(display, anchor);
      // Each run's newest frame, decoded (a decoder each: one task a run).
      std::vector<const Image*> frame_of(runs);
      std::vector<Camera> pose_of(runs);
      {
        std::vector<std::future<void>> decodes;
        for (std::size_t r = 0; r < runs; ++r)
          decodes.push_back(
              std::async(std::launch::async, [&, r] { frame_of[r] = players[r].shown_frame(t, pose_of[r]); }));
        for (auto& d : decodes) d.get();
      }
      for (std::size_t r = 0; r < runs; ++r)
        if (!frame_of[r]) throw std::runtime_error(session + ": no decoded frame by " + std::to_string(t) + " ms");
      // --parts: the renders (one renderer, so here, in turn) of the server's cut at the display
      // pose and of each run's shown pose at its frame's bound, raw.
      Image cut;
      std::vector<Image> raw(parts ? runs : 0);
      if (parts) {
        view->set_options(detail(lod_bound_of(players[0])));
        view->render(display, cut);
        for (std::size_t r = 0; r < runs; ++r) {
          view->set_options(detail(lod_bound_of(players[r])));
          view->render(pose_of[r], raw[r]);
        }
      }
      // The rows' re-projections and scores are independent: one task each.
      std::vector<Image> shown(players.size());
      std::vector<Image> frames(players.size());
      std::vector<std::future<void>> tasks;
      tasks.push_back(std::async(std::launch::async, [&] { rows[0].add(full, want); }));
      tasks.push_back(std::async(std::launch::async, [&] { rows[1].add(anchor, want); }));
      if (parts) {
        rows[cut_row].detail.push_back(lod_bound_of(players[0]));
        tasks.push_back(std::async(std::launch::async, [&] { rows[cut_row].add(cut, want); }));
      }
      for (std::size_t r = 0; r < players.size(); ++r)
        tasks.push_back(std::async(std::launch::async, [&, r] {
          const Image* frame = frame_of[r];
          const Camera& frame_pose = pose_of[r];
          shown[r] = stretched(page_shows(*frame, frame_pose, display, players[r].recording(), plane_depth),
                               display.width, display.height);
          rows[2 + r].add(shown[r], want);
          if (plain) {
            rows[2 + runs + r].add(stretched(*frame, display.width, display.height), want);
            rows[2 + runs + r].detail.push_back(players[r].shown_age_ms(t));
          }
          if (centre) {
            const double depth = centre_depth(r, players[r], frame_pose);
            rows[centre_row + r].add(stretched(page_shows(*frame, frame_pose, display, players[r].recording(), depth),
                                               display.width, display.height),
                                     want);
            rows[centre_row + r].detail.push_back(players[r].shown_age_ms(t));
          }
          if (depth_warp) {
            const auto& grid =
                players[r].recording().frames[static_cast<std::size_t>(players[r].shown_index())].depth_grid;
            const DepthGrid depth = grid ? server::unpack_depth_grid(*grid) : DepthGrid{};
            const double plane = page_plane_depth(frame_pose, display, players[r].recording(), plane_depth);
            const auto warped = [&](const Image& picture) {
              return stretched(
                  depth_warp_picture(picture, page_pose_of(frame_pose), page_pose_of(display), depth, plane),
                  display.width, display.height);
            };
            rows[warp_row + r].add(warped(*frame), want);
            rows[warp_row + r].detail.push_back(players[r].shown_age_ms(t));
            if (parts) {
              rows[raw_row + r].add(warped(raw[r]), want);
              rows[raw_row + r].detail.push_back(players[r].shown_age_ms(t));
            }
          }
          rows[2 + r].detail.push_back(players[r].shown_age_ms(t));
          if (!png_dir.empty()) frames[r] = *frame;
        }));
      for (auto& task : tasks) task.get();
      if (!png_dir.empty() && rows[1 + runs].psnr.back() < worst) {  // the last run's worst refresh
        worst = rows[1 + runs].psnr.back();
        const std::string base = png_dir + "/" + session + "_worst_";
        write_png(want, base + "ideal.png");
        write_png(frames.back(), base + "frame.png");
        write_png(shown.back(), base + "shown.png");
        write_png(anchor, base + "anchor.png");
      }
    }
    return rows;
  }
};

}  // namespace

int main(int argc, char** argv) {
  try {
    const tools::Args args(argc, argv,
                           {"--scene", "--cache-dir", "--run", "--renderer", "--aa", "--refresh-hz", "--warmup-s",
                            "--every", "--anchor-budget", "--json", "--png-dir", "--help!", "--plain!", "--plane-depth",
                            "--centre-plane!", "--depth-warp!", "--parts!"});
    if (args.has("--help")) {
      std::cout << kUsage;
      return 0;
    }
    const std::vector<RunSpec> runs = parse_runs(args.require("--run"));
    Scorer s;
    s.aa = args.get_int("--aa", 4);
    s.refresh_hz = args.get_double("--refresh-hz", 60);
    s.warmup_s = args.get_double("--warmup-s", 1);
    s.every = args.get_int("--every", 1);
    s.budget = static_cast<std::uint64_t>(args.get_double("--anchor-budget", 1.5e6));
    s.png_dir = args.get("--png-dir");
    s.plain = args.has("--plain");
    s.plane_depth = args.get_double("--plane-depth", 0);
    s.centre = args.has("--centre-plane");
    s.parts = args.has("--parts");
    s.depth_warp = args.has("--depth-warp") || s.parts;
    if (s.aa < 1 || s.refresh_hz <= 0 || s.every < 1)
      throw std::invalid_argument("--aa and --every must be >= 1, --refresh-hz > 0");
    if (!s.png_dir.empty()) std::filesystem::create_directories(s.png_dir);
    server::SceneWithLodOptions lod;
    lod.lod = server::LodMode::read;
    lod.cache_dir = args.get("--cache-dir");
    lod.log = [](const std::string& line) { std::cout << "scene: " << line << "\n"; };
    s.model = std::make_shared<const GaussianModel>(server::load_scene_with_lod(args.require("--scene"), lod, {}));
    s.counter = std::make_unique<server::CutCounter>(*s.model);
    if (s.centre) s.chunks = chunk_bounds_of(*s.model);
    const std::string kind = args.get("--renderer", "auto");
    std::string why;
    s.ideal = make_renderer(kind, s.model, detail(0.0f), &why);
    s.view = make_renderer(kind, s.model, detail(0.0f));
    std::cout << "scene " << args.get("--scene") << ": " << s.model->size() << " Gaussians; renderer "
              << s.ideal->name() << (why.empty() ? "" : " (" + why + ")") << "\n";

    std::vector<std::string> names;
    std::vector<std::vector<std::string>> sessions;
    for (const RunSpec& r : runs) {
      names.push_back(r.name);
      sessions.push_back(session_dirs(r.dir));
    }
    nlohmann::json report = {{"aa", s.aa},       {"refresh_hz", s.refresh_hz}, {"warmup_s", s.warmup_s},
                             {"every", s.every}, {"anchor_budget", s.budget},  {"sessions", nlohmann::json::array()}};
    std::map<std::string, Row> pooled;
    std::vector<std::string> order;
    std::printf("%-12s %-22s %8s %9s %9s %9s %9s %9s\n", "session", "picture", "refresh", "PSNR", "PSNR p5", "SSIM",
                "SSIM p5", "px | age");
    for (std::size_t k = 0; k < sessions.front().size(); ++k) {
      // The first run's session k and the session of the same folder name in every other run
      // (a loaded run holds more sessions: those the others have are scored).
      const std::string session = std::filesystem::path(sessions.front()[k]).filename().string();
      std::vector<RecordingPlayer> players;
      for (std::size_t r = 0; r < sessions.size(); ++r) {
        auto it = std::find_if(sessions[r].begin(), sessions[r].end(), [&](const std::string& d) {
          return std::filesystem::path(d).filename().string() == session || sessions[r].size() == 1;
        });
        if (it == sessions[r].end()) throw std::runtime_error("run " + names[r] + " has no " + session);
        players.emplace_back(loadgen::read_recording(*it));
      }
      const auto& a = players.front().recording();
      for (const auto& p : players) {
        const auto& b = p.recording();
        if (b.width != a.width || b.height != a.height || b.trace_spec != a.trace_spec || b.offset_s != a.offset_s)
          throw std::runtime_error("session " + std::to_string(k) + " differs between runs (size, trace or offset)");
      }
      const std::vector<Row> rows = s.score(names, players, session);
      nlohmann::json sj = {{"session", session},
                           {"trace", a.trace_spec},
                           {"width", a.width},
                           {"height", a.height},
                           {"link_rtt_ms", a.link.rtt_ms},
                           {"link_rate_mbit", a.link.rate_mbit},
                           {"rows", nlohmann::json::array()}};
      for (const Row& row : rows) {
        print_row(session, row);
        sj["rows"].push_back(row_json(row));
        sj["rows"].back()["name"] = row.name;
        if (!pooled.count(row.name)) order.push_back(row.name);
        Row& all = pooled[row.name];
        all.name = row.name;
        all.psnr.insert(all.psnr.end(), row.psnr.begin(), row.psnr.end());
        all.ssim.insert(all.ssim.end(), row.ssim.begin(), row.ssim.end());
        all.detail.insert(all.detail.end(), row.detail.begin(), row.detail.end());
      }
      report["sessions"].push_back(sj);
    }
    report["pooled"] = nlohmann::json::array();
    for (const std::string& name : order) {
      print_row("all", pooled[name]);
      nlohmann::json j = row_json(pooled[name]);
      j.erase("psnr_db");
      j.erase("ssim");
      j["name"] = name;
      report["pooled"].push_back(j);
    }
    if (args.has("--json")) {
      std::ofstream(args.get("--json")) << report.dump(1) << "\n";
      std::cout << "JSON: " << args.get("--json") << "\n";
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "catgs-shown: " << e.what() << "\n" << kUsage;
    return 2;
  }
}
