#include "process/thread_name.h"

#if defined(__linux__)
#include <pthread.h>
#endif

namespace catgs::server {

void name_this_thread(const std::string& name) {
#if defined(__linux__)
  // pthread_setname_np fails (ERANGE) past 15 characters rather than cutting: cut here.
  (void)pthread_setname_np(pthread_self(), name.substr(0, 15).c_str());
#else
  (void)name;
#endif
}

}  // namespace catgs::server
