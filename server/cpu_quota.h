// How many CPU cores this process may use: the default for --threads (server_options.cpp), so a
// container limited to 4 CPUs on a 64-core node (Kubernetes resources.limits.cpu, docker --cpus,
// --cpuset-cpus) runs 4 workers rather than 64 that the kernel then throttles.
#pragma once

#include <optional>
#include <string>

namespace catgs::server {

// The CFS bandwidth limit of this process's cgroup in cores (quota / period), or nullopt where
// none is set. cgroup v2: `cpu.max` ("QUOTA PERIOD" or "max PERIOD") in the process's own cgroup
// (/proc/self/cgroup's "0::PATH" under `root`), else at `root` itself (a container's cgroup
// namespace mounts its own cgroup there). cgroup v1: cpu.cfs_quota_us (-1: none) and
// cpu.cfs_period_us under `root`/cpu or `root`/cpu,cpuacct. Unreadable or malformed files count
// as no limit. `root` and `self_cgroup` are parameters so that tests can point at fake trees.
std::optional<double> cgroup_cpu_limit(const std::string& root = "/sys/fs/cgroup",
                                       const std::string& self_cgroup = "/proc/self/cgroup");

// min(CPUs in this thread's affinity mask, the cgroup limit rounded up), at least 1.
int usable_cores();

}  // namespace catgs::server
