// catgs-scene load-bench: how long a scene takes to load, plain and through the scene cache,
// from a cold and a warm page cache, with each load's peak memory (issue 37). Prints a table and
// writes JSON; it never fails on time.
//
// Every measurement runs in a child process of its own (fork), so its peak resident set (VmHWM,
// reset through /proc/self/clear_refs at the child's start) is that load's alone. "cold" drops the
// file's pages from the page cache first (posix_fadvise DONTNEED: no root needed; pages another
// process maps stay), so the file is read from the disk; "warm" loads it right after a load.
// Warm rows keep the best of --repeat loads.
#pragma once

#include <string>
#include <vector>

namespace catgs::tools {

struct LoadBenchOptions {
  std::vector<std::string> scenes;
  int threads = 0;        // LoadOptions::threads (0: every hardware thread)
  int repeat = 3;         // warm loads per row (the best is kept); cold rows run once
  bool reference = true;  // also time the serial reference reader (slow on big files)
  // Also time the upload to CUDA device 0 after each load (a CUDA renderer made for the model:
  // DeviceScene::upload, its half SH and chunk bounds included), after a warm-up that creates
  // the CUDA context; each row's "upload s" is the best load's upload. Needs a CUDA build.
  bool upload = false;
  std::string cache_dir;  // where the caches go (empty: beside each scene)
  std::string json_path;  // empty: no JSON
};

// Runs the benchmark, prints its tables to stdout; returns 0, or 1 when a scene failed to load
// (the error is printed and the other scenes still run).
int run_load_bench(const LoadBenchOptions& options);

}  // namespace catgs::tools
