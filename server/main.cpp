// catgs-server: the CaT-GS Stream remote-rendering server (DESIGN.md "Server"). Exit codes: 0
// after a clean shutdown (or --help), 2 for bad options, 1 for any other error (a scene, codec
// or port that cannot be had).
#include <iostream>

extern "C" {
#include <libavutil/log.h>
}

#include "server.h"
#include "server_options.h"

int main(int argc, char** argv) {
  using namespace catgs::server;
  ServerOptions options;
  try {
    if (!parse_server_options(argc, argv, options)) return 0;
  } catch (const std::exception& e) {
    std::cerr << "catgs-server: " << e.what() << "\n";
    return 2;
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
