#include "test_data.h"

#include <cstdlib>
#include <filesystem>
#include <map>
#include <random>

#include "scene/ply_io.h"

namespace fs = std::filesystem;

namespace catgs::test {

std::string data_dir() {
  const char* env = std::getenv("CATGS_DATA_DIR");
  const std::string dir = env && *env ? env : CATGS_DATA_DIR_DEFAULT;
  return fs::is_directory(dir) ? dir : "";
}

std::string data_file(const std::string& relative) {
  const std::string dir = data_dir();
  if (dir.empty()) return "";
  const fs::path p = fs::path(dir) / relative;
  return fs::exists(p) ? p.string() : "";
}

std::string bundled_scene() { return std::string(CATGS_ASSETS_DIR) + "/scenes/biker.compressed.ply"; }

std::string temp_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const fs::path p =
      fs::temp_directory_path() / "catgs_tests" / (std::string(info->test_suite_name()) + "." + info->name());
  fs::remove_all(p);
  fs::create_directories(p);
  return p.string();
}

std::shared_ptr<const GaussianModel> cached_scene(const std::string& path) {
  static std::map<std::string, std::shared_ptr<const GaussianModel>> cache;
  auto& s = cache[path];
  if (!s) s = std::make_shared<GaussianModel>(load_scene(path));
  return s;
}

std::shared_ptr<const GaussianModel> giant_gaussians(std::size_t n, float log_scale) {
  auto m = std::make_shared<GaussianModel>();
  m->resize(n);
  std::mt19937 rng(22);
  std::uniform_real_distribution<float> u(-0.5f, 0.5f);
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      m->means[3 * i + a] = u(rng);
      m->log_scales[3 * i + a] = log_scale;
    }
    m->rotations[4 * i] = 1.0f;
    m->opacity_logits[i] = 5.0f;
  }
  return m;
}

}  // namespace catgs::test
