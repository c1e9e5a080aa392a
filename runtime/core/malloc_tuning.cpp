#include "runtime/core/malloc_tuning.h"

#include <cstdlib>
#include <cstring>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace poseforest::core {

bool KeepFreedMemory() {
#if defined(__GLIBC__)
  static const bool applied = [] {
    const char* tunables = std::getenv("GLIBC_TUNABLES");
    if (tunables != nullptr && std::strstr(tunables, "glibc.malloc.") != nullptr) return false;
    // Setting either threshold explicitly also disables glibc's dynamic adjustment of both.
    const bool mmap_ok = ::mallopt(M_MMAP_THRESHOLD, 32 << 20) == 1;
    const bool trim_ok = ::mallopt(M_TRIM_THRESHOLD, 128 << 20) == 1;
    return mmap_ok && trim_ok;
  }();
  return applied;
#else
  return false;
#endif
}

}  // namespace poseforest::core
