// Names the calling thread (Linux: /proc/PID/task/TID/comm, what top -H, perf and the GPU
// machine's ramps show), so a host profile tells the server's threads apart: "catgs-lws" (the
// transport's service thread), "catgs-lane3" (a render lane), "catgs-pool7" (an Asio worker).
// Threads a named thread starts inherit its name; x264's sliced threads are renamed "catgs-x264"
// when their encoder opens (encode/x264_encoder.cpp).
// Names past 15 characters are cut to 15 (the kernel's limit); elsewhere than Linux, nothing. A
// failure is ignored: a name only helps a profile read.
#pragma once

#include <string>

namespace catgs::server {

void name_this_thread(const std::string& name);

}  // namespace catgs::server
