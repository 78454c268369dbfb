// The parallel order statistics the first view uses (process/order_statistics.h) against
// std::nth_element and std::sort, on random values and on a real scene's distances.
#include <algorithm>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "scene/ply_io.h"
#include "process/order_statistics.h"
#include "test_data.h"

namespace catgs::server {
namespace {

float serial_kth(std::vector<float> v, std::size_t k) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

void expect_like_the_std(const std::vector<float>& v, const char* what) {
  for (const double q : {0.0, 0.02, 0.25, 0.5, 0.95, 1.0}) {
    const auto k = static_cast<std::size_t>(q * static_cast<double>(v.size() - 1));
    EXPECT_EQ(kth_smallest(v, k), serial_kth(v, k)) << what << " q " << q;
  }
  std::vector<float> a(v), b(v);
  std::sort(a.begin(), a.end());
  parallel_sort(b);
  EXPECT_EQ(a, b) << what;
}

TEST(OrderStatistics, AsNthElementAndSortOnRandomValues) {
  std::mt19937 rng(37);
  std::normal_distribution<float> normal(0.0f, 3.0f);
  std::uniform_int_distribution<int> few(-3, 3);
  for (const std::size_t n : {std::size_t{1}, std::size_t{1000}, std::size_t{1} << 20, (std::size_t{1} << 21) + 17}) {
    std::vector<float> spread(n), ties(n);
    for (std::size_t i = 0; i < n; ++i) {
      spread[i] = normal(rng);
      ties[i] = static_cast<float>(few(rng));  // a few values, each many times
    }
    expect_like_the_std(spread, "normal");
    expect_like_the_std(ties, "ties");
  }
  EXPECT_THROW(kth_smallest(std::vector<float>(3), 3), std::invalid_argument);
}

TEST(OrderStatistics, AsNthElementOnRealDistances) {
  CATGS_REQUIRE_DATA(path, "scenes/tumblewood_sh2.ply");
  const GaussianModel m = load_scene(path);
  std::vector<float> d(m.size()), x(m.size());
  for (std::size_t i = 0; i < m.size(); ++i) {
    d[i] = std::hypot(m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]);
    x[i] = m.means[3 * i];
  }
  expect_like_the_std(d, "distances");
  expect_like_the_std(x, "x");
}

}  // namespace
}  // namespace catgs::server
