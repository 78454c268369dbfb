// cgroup CPU limits read from fake cgroup trees (v2 own cgroup, v2 root, v1), and the default
// --threads following them.
#include "cpu_quota.h"

#include <filesystem>
#include <fstream>
#include <thread>

#include <gtest/gtest.h>

#include "server_options.h"
#include "test_data.h"

namespace catgs::server {
namespace {

void write(const std::string& path, const std::string& text) {
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  std::ofstream(path) << text;
}

TEST(CpuQuota, CgroupV2OwnCgroupFirst) {
  const std::string root = test::temp_dir() + "/cg", self = root + "/self_cgroup";
  write(self, "0::/kubepods/pod1/c1\n");
  write(root + "/kubepods/pod1/c1/cpu.max", "250000 100000\n");
  write(root + "/cpu.max", "max 100000\n");
  ASSERT_TRUE(cgroup_cpu_limit(root, self).has_value());
  EXPECT_DOUBLE_EQ(*cgroup_cpu_limit(root, self), 2.5);
}

TEST(CpuQuota, CgroupV2NamespaceRootAndNoLimit) {
  const std::string root = test::temp_dir() + "/cg", self = root + "/self_cgroup";
  write(self, "0::/\n");
  write(root + "/cpu.max", "150000 100000\n");
  EXPECT_DOUBLE_EQ(cgroup_cpu_limit(root, self).value_or(-1), 1.5);
  write(root + "/cpu.max", "max 100000\n");
  EXPECT_FALSE(cgroup_cpu_limit(root, self).has_value());
  write(root + "/cpu.max", "garbage\n");
  EXPECT_FALSE(cgroup_cpu_limit(root, self).has_value());
}

TEST(CpuQuota, CgroupV1Cfs) {
  const std::string root = test::temp_dir() + "/cg", self = root + "/none";
  write(root + "/cpu,cpuacct/cpu.cfs_quota_us", "400000\n");
  write(root + "/cpu,cpuacct/cpu.cfs_period_us", "100000\n");
  EXPECT_DOUBLE_EQ(cgroup_cpu_limit(root, self).value_or(-1), 4.0);
  write(root + "/cpu,cpuacct/cpu.cfs_quota_us", "-1\n");
  EXPECT_FALSE(cgroup_cpu_limit(root, self).has_value());
}

// The default --threads is max(4, usable cores), at most the host's cores; an explicit one stays.
TEST(CpuQuota, DefaultThreadsFollowUsableCores) {
  ServerOptions o;
  const char* argv[] = {"catgs-server", "--scene", "x.ply"};
  ASSERT_TRUE(parse_server_options(3, const_cast<char**>(argv), o));
  EXPECT_EQ(o.threads, std::max(4, usable_cores()));
  EXPECT_LE(usable_cores(), static_cast<int>(std::max(1u, std::thread::hardware_concurrency())));
  ServerOptions p;
  const char* argv2[] = {"catgs-server", "--scene", "x.ply", "--threads", "3"};
  ASSERT_TRUE(parse_server_options(5, const_cast<char**>(argv2), p));
  EXPECT_EQ(p.threads, 3);
}

}  // namespace
}  // namespace catgs::server
