// catgs-server: the CaT-GS Stream remote-rendering server (docs/DESIGN.md "Server"). Exit
// codes: 0 after a clean shutdown (or --help), 2 for bad options, 1 for any other error (a scene,
// codec or port that cannot be had). `--probe URL` only probes: 0 for a 2xx answer, 1 otherwise.
#include <cstdlib>
#include <iostream>

extern "C" {
#include <libavutil/log.h>
}

#include "base/allocation_faults.h"
#include "server.h"
#include "server_options.h"
#include "transport/probe.h"

namespace {

// Within Docker's default HEALTHCHECK timeout (30 s) and Kubernetes' exec probes' (1 s default,
// set higher in deploy/k8s): a probe answers well inside it or reports the server unhealthy.
constexpr int kProbeTimeoutMs = 3000;

int run_probe(const std::string& url) {
  std::string error;
  const int status = catgs::server::probe_http(url, kProbeTimeoutMs, &error);
  if (status < 0) {
    std::cerr << "catgs-server --probe " << url << ": no answer (" << error << ")\n";
    return 1;
  }
  std::cout << url << " " << status << "\n";
  return status >= 200 && status < 300 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace catgs::server;
  ServerOptions options;
  try {
    if (!parse_server_options(argc, argv, options)) return 0;
    // From the environment rather than the command line: /proc/PID/environ is readable by this
    // user and root only, /proc/PID/cmdline by everyone.
    resolve_access_tokens(options, std::getenv("CATGS_TOKEN"), std::cerr);
    // Fault injection for soak runs (issue 73; base/allocation_faults.h): renderer buffer
    // allocations fail at random, as on a GPU another process fills.
    if (catgs::AllocationFault fault = catgs::allocation_fault_from_environment()) {
      std::cerr << "catgs-server: CATGS_FAIL_ALLOCATIONS=" << std::getenv("CATGS_FAIL_ALLOCATIONS")
                << ": renderer buffer allocations fail at random (a fault-injection run)\n";
      catgs::set_allocation_fault(std::move(fault));
    }
  } catch (const std::exception& e) {
    std::cerr << "catgs-server: " << e.what() << "\n";
    return 2;
  }
  if (!options.probe_url.empty()) {
    try {
      return run_probe(options.probe_url);
    } catch (const std::exception& e) {
      std::cerr << "catgs-server: " << e.what() << "\n";
      return 2;
    }
  }
  av_log_set_level(AV_LOG_ERROR);  // x264 prints a banner per encoder otherwise
  try {
    Server server(options);
    return server.run();
  } catch (const std::exception& e) {
    std::cerr << "catgs-server: " << e.what() << "\n";
    return 1;
  }
}
