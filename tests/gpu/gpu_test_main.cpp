// catgs-gpu-tests: the GPU tests' main (GoogleTest; one file a topic, tests/gpu/*_test.cpp).
//
// ctest runs each test in a process of its own (label gpu; gpu_quick: the quick subset; gpu_large:
// the 8192 px, 2^31-entry and 49-copy city tests). The environment (gpu_test_support.h) says where
// the scenes are and where the table goes; scripts/gpu_run.sh sets it.
//
// The flags of the program before GoogleTest still work (scripts/gpu_before_after.sh and earlier
// commands run it so), after any --gtest_* flags:
//   catgs-gpu-tests --scenes DIR [--traces DIR] [--out table.md] [--quick] [--skip-large]
//                   [--only budget|passes|lod|hostile]
//   --scenes, --traces, --out  set CATGS_GPU_SCENES, CATGS_GPU_TRACES, CATGS_GPU_OUT; --scenes also
//                              CATGS_GPU_STRICT=1 (no device or a missing file fails, as before)
//   --quick                    CATGS_GPU_QUICK=1, and the quick subset (without --only)
//   --only X                   --gtest_filter: budget Budget.*, passes Budget.*:Passes.*, lod Lod.*,
//                              hostile Hostile.*
//   --skip-large               leaves the gpu_large tests out
// An explicit --gtest_filter wins over --quick, --only and --skip-large.
#include <cstdio>
#include <cstdlib>
#include <string>

#include <gtest/gtest.h>

#include "gpu_test_support.h"

#ifndef CATGS_GPU_QUICK_FILTER
#error "CATGS_GPU_QUICK_FILTER (tests/gpu/CMakeLists.txt) is not defined"
#endif
#ifndef CATGS_GPU_LARGE_FILTER
#error "CATGS_GPU_LARGE_FILTER (tests/gpu/CMakeLists.txt) is not defined"
#endif

namespace {

// Prints the device and the table's header before the first test (not when only listing them).
class Header : public ::testing::Environment {
 public:
  void SetUp() override {
    const std::string why = catgs::gputest::device_missing();
    if (!why.empty()) {
      std::fprintf(stderr, "%s\n", why.c_str());
      return;
    }
    std::printf("GPU: %s\n", catgs::gputest::gpu_name().c_str());
    std::printf("%-10s %-16s %-7s %-8s %8s %10s %4s %12s %12s  %s\n", "test", "scene", "view", "pipeline", "PSNR dB",
                "max|err|", "8bit", "list (ref)", "list (gpu)", "result");
    std::fflush(stdout);
  }
};

int usage(const std::string& what) {
  std::fprintf(stderr,
               "catgs-gpu-tests: %s\nusage: catgs-gpu-tests [--gtest_* ...] [--scenes DIR] [--traces DIR] [--out "
               "table.md] [--quick] [--skip-large] [--only budget|passes|lod|hostile]\n",
               what.c_str());
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);  // takes the --gtest_* flags out of argv
  std::string only;
  bool quick = false, skip_large = false;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i], value;
    if (const auto eq = a.find('='); a.rfind("--", 0) == 0 && eq != std::string::npos) {
      value = a.substr(eq + 1);
      a.resize(eq);
    } else if ((a == "--scenes" || a == "--traces" || a == "--out" || a == "--only") && i + 1 < argc) {
      value = argv[++i];
    }
    const bool needs_value = a == "--scenes" || a == "--traces" || a == "--out" || a == "--only";
    if (needs_value && value.empty()) return usage(a + " needs a value");
    if (a == "--scenes") {
      setenv("CATGS_GPU_SCENES", value.c_str(), 1);
      setenv("CATGS_GPU_STRICT", "1", 0);
    } else if (a == "--traces") {
      setenv("CATGS_GPU_TRACES", value.c_str(), 1);
    } else if (a == "--out") {
      setenv("CATGS_GPU_OUT", value.c_str(), 1);
    } else if (a == "--only") {
      only = value;
    } else if (a == "--quick") {
      quick = true;
      setenv("CATGS_GPU_QUICK", "1", 1);
    } else if (a == "--skip-large") {
      skip_large = true;
    } else {
      return usage("unknown argument '" + std::string(argv[i]) + "'");
    }
  }
  if (GTEST_FLAG_GET(filter) == "*" && (quick || skip_large || !only.empty())) {
    std::string positive = "*";
    if (only == "budget")
      positive = "Budget.*";
    else if (only == "passes")
      positive = "Budget.*:Passes.*";
    else if (only == "lod")
      positive = "Lod.*";
    else if (only == "hostile")
      positive = "Hostile.*";
    else if (!only.empty())
      return usage("--only takes budget, passes, lod or hostile");
    else if (quick)
      positive = CATGS_GPU_QUICK_FILTER;
    GTEST_FLAG_SET(filter, positive + (skip_large ? std::string("-") + CATGS_GPU_LARGE_FILTER : std::string()));
  }
  ::testing::AddGlobalTestEnvironment(new Header);
  catgs::gputest::install_row_listener();
  const int rc = RUN_ALL_TESTS();
  if (!GTEST_FLAG_GET(list_tests)) catgs::gputest::finish_report();
  return rc;
}
