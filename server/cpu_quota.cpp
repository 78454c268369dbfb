#include "cpu_quota.h"

#include <sched.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <thread>

namespace catgs::server {

namespace {

// "QUOTA PERIOD" of cgroup v2's cpu.max; "max" (or anything unreadable): no limit.
std::optional<double> read_cpu_max(const std::string& path) {
  std::ifstream in(path);
  std::string quota;
  double period = 0;
  if (!(in >> quota >> period) || quota == "max" || !(period > 0)) return std::nullopt;
  char* end = nullptr;
  const double q = std::strtod(quota.c_str(), &end);
  if (end == quota.c_str() || *end != '\0' || !(q > 0)) return std::nullopt;
  return q / period;
}

// cgroup v1: cpu.cfs_quota_us / cpu.cfs_period_us in `dir`; quota -1: no limit.
std::optional<double> read_cfs(const std::string& dir) {
  std::ifstream q(dir + "/cpu.cfs_quota_us"), p(dir + "/cpu.cfs_period_us");
  double quota = 0, period = 0;
  if (!(q >> quota) || !(p >> period) || !(quota > 0) || !(period > 0)) return std::nullopt;
  return quota / period;
}

// The cgroup v2 path of this process ("0::/kubepods/..."), or "" (v1 only, or unreadable).
std::string own_v2_path(const std::string& self_cgroup) {
  std::ifstream in(self_cgroup);
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("0::", 0) == 0) return line.substr(3);
  return "";
}

}  // namespace

std::optional<double> cgroup_cpu_limit(const std::string& root, const std::string& self_cgroup) {
  const std::string own = own_v2_path(self_cgroup);
  if (!own.empty() && own != "/")
    if (auto limit = read_cpu_max(root + own + "/cpu.max")) return limit;
  if (auto limit = read_cpu_max(root + "/cpu.max")) return limit;
  for (const char* dir : {"/cpu", "/cpu,cpuacct"})
    if (auto limit = read_cfs(root + dir)) return limit;
  return std::nullopt;
}

int usable_cores() {
  int cores = static_cast<int>(std::thread::hardware_concurrency());
  cpu_set_t set;
  if (sched_getaffinity(0, sizeof(set), &set) == 0) cores = CPU_COUNT(&set);
  if (const auto limit = cgroup_cpu_limit()) cores = std::min(cores, static_cast<int>(std::ceil(*limit)));
  return std::max(1, cores);
}

}  // namespace catgs::server
