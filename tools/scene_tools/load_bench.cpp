// catgs-scene load-bench (load_bench.h).
#include "scene_tools/load_bench.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <stdexcept>
#include <thread>

#include <nlohmann/json.hpp>

#include "forward_model/chunk_bounds.h"
#include "forward_model/sh_storage.h"
#include "renderer/renderer.h"
#include "scene/load_blocks.h"
#include "scene/ply_io.h"
#include "scene/scene_cache.h"
#include "scene/scene_peek.h"

namespace catgs::tools {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// What a child sends back: up to 8 timings (s), its peak resident set, an error.
struct ChildResult {
  double seconds[12] = {};
  double base_mib = 0;  // resident at the start (the program, its libraries, a CUDA context)
  double peak_mib = 0;  // peak resident
  char error[512] = {};
};

// Resets the peak resident set (VmHWM) to the current one (Linux >= 4.0).
void reset_peak() { std::ofstream("/proc/self/clear_refs") << "5"; }
// A /proc/self/status field (kB) in MiB.
double status_mib(const std::string& field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(field + ":", 0) == 0) return std::stod(line.substr(field.size() + 1)) / 1024.0;
  return 0;
}
double peak_mib() { return status_mib("VmHWM"); }

// Runs fn in a forked child and returns what it filled in (its peak memory its own).
ChildResult in_child(const std::function<void(ChildResult&)>& fn) {
  int fds[2];
  if (::pipe(fds) != 0) throw std::runtime_error("pipe failed");
  std::cout.flush();
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    ::close(fds[0]);
    ChildResult r;
    try {
      reset_peak();
      r.base_mib = status_mib("VmRSS");
      fn(r);
      if (r.peak_mib == 0) r.peak_mib = peak_mib();
    } catch (const std::exception& e) {
      std::snprintf(r.error, sizeof r.error, "%s", e.what());
    }
    const ssize_t w = ::write(fds[1], &r, sizeof r);
    ::_exit(w == static_cast<ssize_t>(sizeof r) ? 0 : 1);
  }
  ::close(fds[1]);
  ChildResult r;
  const ssize_t got = ::read(fds[0], &r, sizeof r);
  ::close(fds[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  if (got != static_cast<ssize_t>(sizeof r)) std::snprintf(r.error, sizeof r.error, "the measuring process died");
  return r;
}

// Drops `path`'s pages from the page cache (written back first, so dirty pages go too).
void drop_from_page_cache(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error(path + ": cannot open to drop its pages");
  ::fdatasync(fd);
  ::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
  ::close(fd);
}

uint64_t file_bytes(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 ? static_cast<uint64_t>(st.st_size) : 0;
}

// A plain sequential read of the whole file (the disk's or the page cache's rate, for scale).
void read_through(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error(path + ": cannot open");
  std::vector<char> buffer(8 << 20);
  while (::read(fd, buffer.data(), buffer.size()) > 0) {}
  ::close(fd);
}

struct Row {
  std::string mode, cache;  // "plain" / "cache" / "cache write", "cold" / "warm"
  double seconds = 0, bytes = 0, peak_mib = 0;
  double upload_s = -1;  // --upload: of the best load; -1 when not measured
  double base_mib = 0;
  std::string error;
};

struct SceneResult {
  std::string path, cache_path, name;
  uint64_t bytes = 0, cache_bytes = 0, gaussians = 0, model_bytes = 0;
  int sh_degree = 0;
  std::vector<std::pair<std::string, double>> phases_ms;
  std::vector<Row> rows;
  std::string error;
};

uint64_t model_bytes(const GaussianModel& m) {
  return 4 * (m.means.size() + m.log_scales.size() + m.rotations.size() + m.opacity_logits.size() + m.sh.size());
}

// Where the time of a plain load goes, phase by phase (one warm child). The index of each phase's
// time in ChildResult::seconds is its index here.
constexpr const char* kPhases[] = {"read (8 MiB reads)",
                                   "parse, reference (1 thread)",
                                   "parse + validate, load_scene",
                                   "validate (again, alone)",
                                   "model arrays allocated (GaussianModel::resize)",
                                   "chunk bounds",
                                   "SH to half (1 thread)",
                                   "SH to half (load threads, as DeviceScene::upload)",
                                   "scene bounds (1 thread)"};
static_assert(sizeof(kPhases) / sizeof(kPhases[0]) <= sizeof(ChildResult::seconds) / sizeof(double));

void phases(SceneResult& s, const LoadBenchOptions& o) {
  const ChildResult r = in_child([&](ChildResult& out) {
    int k = 0;
    auto t0 = Clock::now();
    auto lap = [&] {  // the time since the last lap into the next phase
      out.seconds[k++] = seconds_since(t0);
      t0 = Clock::now();
    };
    read_through(s.path);
    lap();
    if (o.reference) {
      LoadOptions ref;
      ref.reference = true;
      (void)load_scene(s.path, ref);
    }
    lap();
    const GaussianModel m = load_scene(s.path, LoadOptions{o.threads, false});
    lap();
    m.validate();
    lap();
    {
      GaussianModel empty;
      empty.sh_degree = m.sh_degree;
      empty.resize(m.size());
    }
    lap();
    const auto chunks = chunk_bounds_of(m);
    lap();
    std::vector<uint16_t> half(m.sh.size());
    for (std::size_t i = 0; i < half.size(); ++i) half[i] = fm::half_bits(m.sh[i]);
    lap();
    constexpr std::size_t kBlock = 1 << 20;  // as DeviceScene::upload rounds them
    run_blocks((half.size() + kBlock - 1) / kBlock, o.threads, [&](uint64_t b) {
      const std::size_t end = std::min(half.size(), (b + 1) * kBlock);
      for (std::size_t i = b * kBlock; i < end; ++i) half[i] = fm::half_bits(m.sh[i]);
    });
    lap();
    (void)m.bounds();
    lap();
    if (chunks.empty() || half.empty()) throw std::logic_error("no chunks or SH");
  });
  if (r.error[0]) throw std::runtime_error(r.error);
  for (std::size_t k = 0; k < sizeof(kPhases) / sizeof(kPhases[0]); ++k)
    if (k != 1 || o.reference) s.phases_ms.emplace_back(kPhases[k], 1e3 * r.seconds[k]);
}

// One load row: `repeat` loads in one child, the best kept; cold drops the file first.
Row load_row(const SceneResult& s, const LoadBenchOptions& o, bool cached, bool cold) {
  Row row;
  row.mode = cached ? "cache" : "plain";
  row.cache = cold ? "cold" : "warm";
  row.bytes = static_cast<double>(cached ? s.cache_bytes : s.bytes);
  const int repeat = cold ? 1 : std::max(1, o.repeat);
  const ChildResult r = in_child([&](ChildResult& out) {
    if (o.upload) {  // the CUDA context first: its creation is no part of a load
      auto tiny = std::make_shared<GaussianModel>();
      tiny->resize(1);
      tiny->rotations[0] = 1.0f;
      (void)make_renderer("cuda", tiny, RenderOptions{});
      reset_peak();
      out.base_mib = status_mib("VmRSS");
    }
    double best = 1e300;
    out.seconds[1] = -1;
    for (int k = 0; k < repeat; ++k) {
      if (cold) drop_from_page_cache(cached ? s.cache_path : s.path);
      CachedLoadOptions c;
      c.load.threads = o.threads;
      c.mode = cached ? SceneCacheMode::read : SceneCacheMode::off;
      c.cache_path = s.cache_path;
      CachedLoadReport report;
      const auto t0 = Clock::now();
      auto m = std::make_shared<const GaussianModel>(load_scene_cached(s.path, c, {}, &report));
      const double load_s = seconds_since(t0);
      out.peak_mib = std::max(out.peak_mib, peak_mib());  // the loads', not the uploads'
      if (cached && !report.from_cache) throw std::runtime_error("the cache was not used: " + report.why);
      double upload_s = -1;
      if (o.upload) {
        const auto t1 = Clock::now();
        (void)make_renderer("cuda", m, RenderOptions{});
        upload_s = seconds_since(t1);
      }
      if (load_s < best) {
        best = load_s;
        out.seconds[1] = upload_s;
      }
    }
    out.seconds[0] = best;
  });
  row.seconds = r.seconds[0];
  row.upload_s = r.seconds[1];
  row.base_mib = r.base_mib;
  row.peak_mib = r.peak_mib;
  row.error = r.error;
  return row;
}

Row write_row(const SceneResult& s, const LoadBenchOptions& o) {
  Row row;
  row.mode = "cache write";
  row.cache = "warm";
  row.bytes = static_cast<double>(s.cache_bytes);
  const ChildResult r = in_child([&](ChildResult& out) {
    LoadOptions lo;
    lo.threads = o.threads;
    const GaussianModel m = load_scene(s.path, lo);
    const auto t0 = Clock::now();
    write_scene_cache(m, s.path, s.cache_path, o.threads);
    out.seconds[0] = seconds_since(t0);
  });
  row.seconds = r.seconds[0];
  row.peak_mib = r.peak_mib;
  row.base_mib = r.base_mib;
  row.error = r.error;
  return row;
}

SceneResult bench_scene(const std::string& path, const LoadBenchOptions& o) {
  SceneResult s;
  s.path = path;
  s.name = scene_name(path);
  s.bytes = file_bytes(path);
  s.cache_path =
      o.cache_dir.empty()
          ? scene_cache_path(path)
          : (std::filesystem::path(o.cache_dir) / std::filesystem::path(scene_cache_path(path)).filename()).string();
  const ChildResult info = in_child([&](ChildResult& out) {
    const GaussianModel m = load_scene(path, LoadOptions{o.threads, false});
    out.seconds[0] = static_cast<double>(m.size());
    out.seconds[1] = m.sh_degree;
    out.seconds[2] = static_cast<double>(model_bytes(m));
  });
  if (info.error[0]) {
    s.error = info.error;
    return s;
  }
  s.gaussians = static_cast<uint64_t>(info.seconds[0]);
  s.sh_degree = static_cast<int>(info.seconds[1]);
  s.model_bytes = static_cast<uint64_t>(info.seconds[2]);
  phases(s, o);
  s.rows.push_back(load_row(s, o, false, true));
  s.rows.push_back(load_row(s, o, false, false));
  s.rows.push_back(write_row(s, o));
  s.cache_bytes = file_bytes(s.cache_path);
  s.rows.back().bytes = static_cast<double>(s.cache_bytes);
  s.rows.push_back(load_row(s, o, true, true));
  s.rows.push_back(load_row(s, o, true, false));
  return s;
}

void print(const SceneResult& s, int threads) {
  const auto d = [](uint64_t v) { return static_cast<double>(v); };
  std::printf("\n%s: %s, %.1f MB, %llu Gaussians, SH degree %d, model %.1f MB, cache %.1f MB, %d threads\n",
              s.name.c_str(), s.path.c_str(), d(s.bytes) / 1e6, static_cast<unsigned long long>(s.gaussians),
              s.sh_degree, d(s.model_bytes) / 1e6, d(s.cache_bytes) / 1e6, threads);
  std::printf("| phase (warm page cache) | ms |\n|---|---|\n");
  for (const auto& [name, ms] : s.phases_ms) std::printf("| %s | %.1f |\n", name.c_str(), ms);
  std::printf(
      "\n| load | page cache | s | MB/s (file) | M Gaussians/s | peak RSS MiB | start RSS MiB | (peak - start) / model "
      "| upload s |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|\n");
  for (const Row& r : s.rows) {
    if (!r.error.empty()) {
      std::printf("| %s | %s | failed: %s | | | | | | |\n", r.mode.c_str(), r.cache.c_str(), r.error.c_str());
      continue;
    }
    std::printf("| %s | %s | %.3f | %.0f | %.2f | %.0f | %.0f | %.2f | %s |\n", r.mode.c_str(), r.cache.c_str(),
                r.seconds, r.bytes / 1e6 / r.seconds, d(s.gaussians) / 1e6 / r.seconds, r.peak_mib, r.base_mib,
                (r.peak_mib - r.base_mib) * 1048576.0 / d(s.model_bytes),
                r.upload_s < 0 ? "-" : std::to_string(r.upload_s).substr(0, 5).c_str());
  }
}

nlohmann::json to_json(const SceneResult& s) {
  nlohmann::json j = {{"scene", s.name},
                      {"path", s.path},
                      {"bytes", s.bytes},
                      {"cache_path", s.cache_path},
                      {"cache_bytes", s.cache_bytes},
                      {"gaussians", s.gaussians},
                      {"sh_degree", s.sh_degree},
                      {"model_bytes", s.model_bytes}};
  if (!s.error.empty()) j["error"] = s.error;
  for (const auto& [name, ms] : s.phases_ms) j["phases_ms"][name] = ms;
  for (const Row& r : s.rows) {
    nlohmann::json row = {{"load", r.mode},        {"page_cache", r.cache},      {"seconds", r.seconds},
                          {"file_bytes", r.bytes}, {"peak_rss_mib", r.peak_mib}, {"start_rss_mib", r.base_mib}};
    if (r.seconds > 0) {
      row["mb_per_s"] = r.bytes / 1e6 / r.seconds;
      row["gaussians_per_s"] = static_cast<double>(s.gaussians) / r.seconds;
    }
    if (r.upload_s >= 0) row["upload_seconds"] = r.upload_s;
    if (!r.error.empty()) row["error"] = r.error;
    j["rows"].push_back(row);
  }
  return j;
}

}  // namespace

int run_load_bench(const LoadBenchOptions& o) {
  if (o.scenes.empty()) throw std::invalid_argument("load-bench needs --scenes A[,B...]");
  nlohmann::json out;
  const int threads = load_threads(o.threads);
  out["threads"] = threads;
  out["hardware_threads"] = std::thread::hardware_concurrency();
  out["repeat"] = o.repeat;
  int status = 0;
  for (const std::string& path : o.scenes) {
    SceneResult s;
    try {
      s = bench_scene(path, o);
    } catch (const std::exception& e) {
      s.error = e.what();
    }
    if (!s.error.empty()) {
      std::printf("\n%s: failed: %s\n", path.c_str(), s.error.c_str());
      status = 1;
    } else {
      print(s, threads);
    }
    out["scenes"].push_back(to_json(s));
  }
  if (!o.json_path.empty()) {
    std::ofstream f(o.json_path);
    f << out.dump(2) << "\n";
    if (!f) throw std::runtime_error(o.json_path + ": cannot write");
    std::printf("\nwrote %s\n", o.json_path.c_str());
  }
  return status;
}

}  // namespace catgs::tools
