#include "gpu_test_support.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/image_io.h"
#include "lod/lod_build.h"
#include "scene/ply_io.h"
#include "scene/scene_bounds.h"

#ifndef CATGS_DATA_DIR_DEFAULT
#define CATGS_DATA_DIR_DEFAULT ""
#endif
#ifndef CATGS_ASSETS_DIR
#define CATGS_ASSETS_DIR ""
#endif

namespace fs = std::filesystem;

namespace catgs::gputest {

namespace {

std::string env(const char* name) {
  const char* v = std::getenv(name);
  return v ? v : "";
}

bool env_on(const char* name) {
  const std::string v = env(name);
  return !v.empty() && v != "0";
}

bool exists(const std::string& p) { return !p.empty() && fs::exists(p); }

// A row with the place of the test that added it among all the tests (their registration order,
// which the table keeps however ctest orders the processes).
struct Stored {
  long long ordinal;
  Row row;
};
std::vector<Stored> g_rows;
std::string g_gpu;

long long ordinal_of(const ::testing::TestInfo* cur) {
  const ::testing::UnitTest* ut = ::testing::UnitTest::GetInstance();
  if (!cur) return LLONG_MAX;
  long long k = 0;
  for (int i = 0; i < ut->total_test_suite_count(); ++i) {
    const ::testing::TestSuite* s = ut->GetTestSuite(i);
    for (int j = 0; j < s->total_test_count(); ++j, ++k)
      if (s->GetTestInfo(j) == cur) return k;
  }
  return LLONG_MAX;
}

// The rows file (CATGS_GPU_ROWS): one row a line, tab-separated, with \, tab and newline escaped;
// "gpu<TAB>description" lines name the device.
std::string escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '\\')
      o += "\\\\";
    else if (c == '\t')
      o += "\\t";
    else if (c == '\n')
      o += "\\n";
    else
      o += c;
  }
  return o;
}

std::string unescape(const std::string& s) {
  std::string o;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] != '\\' || i + 1 == s.size()) {
      o += s[i];
      continue;
    }
    const char c = s[++i];
    o += c == 't' ? '\t' : c == 'n' ? '\n' : c;
  }
  return o;
}

std::string serialize(const Stored& s) {
  const Row& r = s.row;
  char nums[200];
  std::snprintf(nums, sizeof nums, "%.17g\t%.17g\t%d\t%lld\t%lld\t%d", r.psnr, r.max_abs, r.max_abs8, r.list_ref,
                r.list_gpu, r.pass ? 1 : 0);
  return "row\t" + std::to_string(s.ordinal) + "\t" + escape(r.test) + "\t" + escape(r.scene) + "\t" + escape(r.view) +
         "\t" + escape(r.pipeline) + "\t" + nums + "\t" + escape(r.note) + "\n";
}

bool parse(const std::string& line, Stored& s) {
  std::vector<std::string> f;
  std::size_t at = 0;
  while (true) {
    const std::size_t tab = line.find('\t', at);
    f.push_back(line.substr(at, tab == std::string::npos ? std::string::npos : tab - at));
    if (tab == std::string::npos) break;
    at = tab + 1;
  }
  if (f.size() != 13 || f[0] != "row") return false;
  s.ordinal = std::atoll(f[1].c_str());
  Row& r = s.row;
  r.test = unescape(f[2]);
  r.scene = unescape(f[3]);
  r.view = unescape(f[4]);
  r.pipeline = unescape(f[5]);
  r.psnr = std::strtod(f[6].c_str(), nullptr);
  r.max_abs = std::strtod(f[7].c_str(), nullptr);
  r.max_abs8 = std::atoi(f[8].c_str());
  r.list_ref = std::atoll(f[9].c_str());
  r.list_gpu = std::atoll(f[10].c_str());
  r.pass = f[11] == "1";
  r.note = unescape(f[12]);
  return true;
}

// Appends this process's rows to `path` and reads back every process's into `all`. Returns the
// file, locked (exclusive) until the caller closes it, or -1 (then `all` is this process's rows).
int merge_rows(const std::string& path, std::vector<Stored>& all, std::string& gpu) {
  all.clear();
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_APPEND, 0644);
  if (fd < 0) {
    std::fprintf(stderr, "catgs-gpu-tests: cannot open %s: rows of this process only\n", path.c_str());
    all = g_rows;
    return -1;
  }
  ::flock(fd, LOCK_EX);
  std::string text = g_gpu.empty() ? std::string() : "gpu\t" + escape(g_gpu) + "\n";
  for (const Stored& s : g_rows) text += serialize(s);
  for (std::size_t done = 0; done < text.size();) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n <= 0) break;
    done += static_cast<std::size_t>(n);
  }
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    Stored s;
    if (line.rfind("gpu\t", 0) == 0)
      gpu = unescape(line.substr(4));
    else if (parse(line, s))
      all.push_back(std::move(s));
  }
  return fd;
}

}  // namespace

Diff compare(const Image& a, const Image& b) {
  Diff d{catgs::psnr_rgba8(a, b), 0.0, 0};
  if (a.rgb.size() == b.rgb.size())
    for (std::size_t i = 0; i < a.rgb.size(); ++i)
      d.max_abs = std::max(d.max_abs, static_cast<double>(std::fabs(a.rgb[i] - b.rgb[i])));
  for (std::size_t i = 0; i < a.rgba8.size(); ++i)
    d.max_abs8 = std::max(d.max_abs8, std::abs(static_cast<int>(a.rgba8[i]) - static_cast<int>(b.rgba8[i])));
  return d;
}

std::string fmt_psnr(double p) {
  char b[32];
  if (std::isinf(p)) return "inf";
  std::snprintf(b, sizeof b, "%.2f", p);
  return b;
}

void add(Row r) {
  std::printf("%-10s %-16s %-7s %-8s %8s %10.3g %4d %12lld %12lld  %s %s\n", r.test.c_str(), r.scene.c_str(),
              r.view.c_str(), r.pipeline.c_str(), fmt_psnr(r.psnr).c_str(), r.max_abs, r.max_abs8, r.list_ref,
              r.list_gpu, r.pass ? "PASS" : "FAIL", r.note.c_str());
  std::fflush(stdout);
  if (!r.pass)
    ADD_FAILURE() << "FAIL: " << r.test << " | " << r.scene << " | " << r.view << " | " << r.pipeline << " | PSNR "
                  << fmt_psnr(r.psnr) << " dB | max abs " << r.max_abs << " | 8-bit " << r.max_abs8 << " | list (ref) "
                  << r.list_ref << " | list (GPU) " << r.list_gpu << " | " << r.note;
  g_rows.push_back({ordinal_of(::testing::UnitTest::GetInstance()->current_test_info()), std::move(r)});
}

namespace {

// A test that failed without a failing row of its own (an exception, a missing file with
// CATGS_GPU_STRICT=1, no device) gets one, "gtest | SUITE | NAME", so the table counts it.
class RowListener : public ::testing::EmptyTestEventListener {
  std::size_t failing_rows_ = 0;
  std::string first_failure_;

  static std::size_t failing_rows() {
    std::size_t n = 0;
    for (const Stored& s : g_rows) n += s.row.pass ? 0 : 1;
    return n;
  }
  void OnTestStart(const ::testing::TestInfo&) override {
    failing_rows_ = failing_rows();
    first_failure_.clear();
  }
  void OnTestPartResult(const ::testing::TestPartResult& r) override {
    if (r.failed() && first_failure_.empty()) first_failure_ = r.message();
  }
  void OnTestEnd(const ::testing::TestInfo& t) override {
    if (!t.result()->Failed() || failing_rows() > failing_rows_) return;
    std::string note = first_failure_;
    for (char& c : note)
      if (c == '\n' || c == '|') c = ' ';
    g_rows.push_back({ordinal_of(&t), Row{"gtest", t.test_suite_name(), t.name(), "-", 0, 0, 0, -1, -1, false,
                                          "failed without a row: " + note}});
  }
};

}  // namespace

void install_row_listener() { ::testing::UnitTest::GetInstance()->listeners().Append(new RowListener); }

// ---- configuration ----

const Config& config() {
  static const Config c = [] {
    Config k;
    std::string data = env("CATGS_DATA_DIR");
    if (data.empty()) data = CATGS_DATA_DIR_DEFAULT;
    const std::string scenes = env("CATGS_GPU_SCENES"), traces = env("CATGS_GPU_TRACES");
    k.scenes = !scenes.empty() ? scenes : data.empty() ? "" : data + "/scenes";
    k.traces = !traces.empty() ? traces : !scenes.empty() ? scenes : data.empty() ? "" : data + "/traces";
    k.quick = env_on("CATGS_GPU_QUICK");
    k.strict = env_on("CATGS_GPU_STRICT");
    k.W = k.quick ? 640 : 1280;
    k.H = k.quick ? 360 : 720;
    return k;
  }();
  return c;
}

std::string scene_path(const std::string& name) {
  const std::string dir = config().scenes;
  std::vector<std::string> candidates;
  if (name == "biker") {
    candidates = {dir + "/biker.compressed.ply", std::string(CATGS_ASSETS_DIR) + "/scenes/biker.compressed.ply"};
  } else if (name == "tumblewood_sh2") {
    // The compact copy (catgs-scene compact; scripts/gpu_run.sh prepare) or the original.
    candidates = {dir + "/tumblewood_sh2.compressed.ply", dir + "/tumblewood_sh2.ply"};
  } else {
    candidates = {dir + "/" + name + ".ply"};
  }
  for (const std::string& p : candidates)
    if (!dir.empty() && exists(p)) return p;
  return "";
}

std::string trace_path(const std::string& name) {
  const std::string p = config().traces + "/" + name + ".cameras.json";
  return !config().traces.empty() && exists(p) ? p : "";
}

std::string missing(const std::vector<std::string>& scenes, const std::vector<std::string>& traces) {
  for (const std::string& s : scenes)
    if (scene_path(s).empty())
      return "scene '" + s + "' not found in '" + config().scenes +
             "' (set CATGS_GPU_SCENES to .carry/scenes, or CATGS_DATA_DIR to ../shared/data)";
  for (const std::string& t : traces)
    if (trace_path(t).empty())
      return "trace '" + t + ".cameras.json' not found in '" + config().traces +
             "' (set CATGS_GPU_TRACES, or CATGS_DATA_DIR to ../shared/data)";
  return "";
}

std::string device_missing() {
  static const std::string why = [] {
    std::string reason;
    if (catgs::cuda::device_usable(&reason)) {
      g_gpu = catgs::cuda::device_description();
      return std::string();
    }
    return "no usable CUDA device: " + reason;
  }();
  return why;
}

const std::string& gpu_name() {
  (void)device_missing();
  return g_gpu;
}

void GpuTest::SetUp() { CATGS_GPU_SKIP_IF(device_missing()); }

// ---- scenes ----

std::shared_ptr<GaussianModel> load(const std::string& path, float scale) {
  auto m = std::make_shared<GaussianModel>(catgs::load_scene(path));
  if (scale != 1.0f) catgs::scale_scene(*m, scale);
  return m;
}

namespace {
SharedScene upload(std::shared_ptr<GaussianModel> m) {
  SharedScene s;
  s.model = std::move(m);
  s.dev = catgs::cuda::DeviceScene::upload(*s.model);
  return s;
}
}  // namespace

const SharedScene& biker() {
  static const SharedScene s = upload(load(scene_path("biker"), 1.0f));
  return s;
}

const SharedScene& flowers() {
  static const SharedScene s = upload(load(scene_path("flowers_sh3"), 1.0f));
  return s;
}

const SharedScene& tumblewood() {
  static const SharedScene s = [] {
    auto m = load(scene_path("tumblewood_sh2"), 10.0f);
    m->name = "tumblewood_sh2";
    return upload(std::move(m));
  }();
  return s;
}

std::vector<Camera> orbit_views(const GaussianModel& m, int w, int h) {
  catgs::GeneratorParams g;
  g.width = w;
  g.height = h;
  g.rate_hz = 1.0;
  g.duration_s = 3.0;
  g.up = {0.0f, -1.0f, 0.0f};
  const auto rb = catgs::robust_bounds(m);
  const glm::vec3 e = rb.extent();
  const float r = 0.6f * std::max(e.x, std::max(e.y, e.z));
  std::vector<Camera> v;
  for (const auto& tc : catgs::make_orbit(rb, r, 0.3f * r, 270.0f, g)) v.push_back(tc.camera);
  return v;
}

catgs::Trace real_trace(const GaussianModel& m, const std::string& cameras, int w, int h, std::size_t frames) {
  auto keys = catgs::load_inria_cameras(cameras);
  catgs::Trace t = catgs::fit_trace_to_scene(keys, m, {0.0f, -1.0f, 0.0f}, 0.6f, 120.0, 0.5, w, h);
  if (t.size() > frames) t.resize(frames);
  return t;
}

catgs::RenderOptions catgs_options() {
  catgs::RenderOptions o;
  o.pipeline = Pipeline::catgs;
  return o;
}

std::shared_ptr<GaussianModel> wall_scene(std::size_t n) {
  auto m = std::make_shared<GaussianModel>();
  m->name = "wall" + std::to_string(n);
  m->sh_degree = 0;
  m->resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    // Depths 5 .. 10: near enough that every Gaussian covers the whole image, and distinct.
    m->means[3 * i + 2] = 5.0f + 1e-5f * static_cast<float>(i);
    for (int a = 0; a < 3; ++a) m->log_scales[3 * i + a] = std::log(40.0f);
    m->rotations[4 * i] = 1.0f;
    m->opacity_logits[i] = 2.0f;  // 0.88: a few layers saturate a pixel
    for (int c = 0; c < 3; ++c)
      m->sh[3 * i + c] = 0.5f * std::sin(0.7f * static_cast<float>(i) + 2.0f * static_cast<float>(c));
  }
  return m;
}

Camera front_camera(int w, int h) { return Camera::from_pose({0.0f, 0.0f, 0.0f}, glm::quat(1, 0, 0, 0), 60.0f, w, h); }

catgs::RenderListBudget pass_budget(std::uint64_t limit) {
  catgs::RenderListBudget b;
  b.max_entries_per_tile = 0;
  b.min_entries = limit;
  b.max_passes = 1000;
  return b;
}

Camera TestCity::view(const catgs::FlyoverParams& flight) const {
  catgs::GeneratorParams g;
  g.width = config().W;
  g.height = config().H;
  g.duration_s = 1.0;
  g.rate_hz = 2.0;
  return catgs::make_city_flyover(layout, flight, g)[1].camera;
}

TestCity test_city(int radius_sq) {
  catgs::CityParams p;
  p.radius_sq = radius_sq;
  p.up = {0.0f, -1.0f, 0.0f};
  TestCity c;
  auto base = catgs::load_scene(scene_path("tumblewood_sh2"));
  c.model = std::make_shared<GaussianModel>(catgs::tile_scene(base, p, &c.layout));
  return c;
}

const CityWithLod& city13_with_lod() {
  static const CityWithLod c = [] {
    CityWithLod k;
    const TestCity city = test_city(4);  // 13 cells
    k.lod = std::make_shared<GaussianModel>(catgs::build_lod(*city.model));
    k.dev = catgs::cuda::DeviceScene::upload(*k.lod);
    k.trace = real_trace(*k.lod, trace_path("mipnerf360_bicycle"), config().W, config().H, 96);
    return k;
  }();
  return c;
}

// ---- the report ----

int finish_report() {
  int failed = 0;
  for (const Stored& s : g_rows) failed += s.row.pass ? 0 : 1;
  const std::string out = env("CATGS_GPU_OUT"), rows_file = env("CATGS_GPU_ROWS");
  std::string gpu = g_gpu;
  std::vector<Stored> all = g_rows;
  const int locked = rows_file.empty() ? -1 : merge_rows(rows_file, all, gpu);
  if (!out.empty()) {
    std::stable_sort(all.begin(), all.end(), [](const Stored& a, const Stored& b) { return a.ordinal < b.ordinal; });
    int all_failed = 0;
    std::ostringstream md;
    md << "GPU: " << gpu
       << "\n\n| test | scene | view | pipeline | PSNR dB | max abs err (float) | max abs err (8-bit) | "
          "render list (ref) | render list (GPU) | result | note |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (const Stored& s : all) {
      const Row& r = s.row;
      all_failed += r.pass ? 0 : 1;
      char err[32];
      std::snprintf(err, sizeof err, "%.3g", r.max_abs);
      md << "| " << r.test << " | " << r.scene << " | " << r.view << " | " << r.pipeline << " | " << fmt_psnr(r.psnr)
         << " | " << err << " | " << r.max_abs8 << " | " << r.list_ref << " | " << r.list_gpu << " | "
         << (r.pass ? "PASS" : "FAIL") << " | " << r.note << " |\n";
    }
    md << "\n" << (all.size() - static_cast<std::size_t>(all_failed)) << " passed, " << all_failed << " failed\n";
    const std::string tmp = out + ".tmp" + std::to_string(::getpid());
    std::ofstream(tmp) << md.str();
    std::error_code ec;
    fs::rename(tmp, out, ec);
    if (ec) std::fprintf(stderr, "catgs-gpu-tests: cannot write %s: %s\n", out.c_str(), ec.message().c_str());
  }
  if (locked >= 0) ::close(locked);  // releases the lock
  std::printf("%zu checks: %zu passed, %d failed\n", g_rows.size(), g_rows.size() - static_cast<std::size_t>(failed),
              failed);
  return failed;
}

}  // namespace catgs::gputest
