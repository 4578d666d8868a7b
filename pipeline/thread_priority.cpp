#include "pipeline/thread_priority.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#ifdef __linux__
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>
#endif

namespace omni {

void LowerThisThreadPriority(int increment, const char* what) {
  if (increment <= 0) return;
#ifdef __linux__
  const auto thread = static_cast<id_t>(syscall(SYS_gettid));
  errno = 0;
  const int current = getpriority(PRIO_PROCESS, thread);
  if (current == -1 && errno != 0) return;
  if (setpriority(PRIO_PROCESS, thread, std::min(19, current + increment)) != 0)
    spdlog::debug("the {} thread's priority was not lowered: {}", what, std::strerror(errno));
#else
  (void)what;
#endif
}

}  // namespace omni
