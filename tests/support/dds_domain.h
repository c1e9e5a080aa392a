#pragma once
// DDS domain ids for tests that no other test process on this machine uses at the same time.
//
// ctest runs test programs in parallel and several start DDS participants, kill some with SIGKILL
// and start others. Two programs that picked the same domain (the old pid-based ids, 1..200, made
// that likely enough) see each other's participants and shared-memory ports, dead ones included,
// and one CI run had a restarted coordinator hear nothing from its workers. Each id is claimed
// with an exclusive flock on /tmp/poseforest-test-domains/<id>.lock, held until the process
// exits (the kernel drops it then, also after a crash), so parallel programs never share one.

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdint>
#include <map>
#include <mutex>
#include <set>
#include <string>

namespace poseforest::testing {

/// The domain of `key` in this process (the same key gives the same id; different keys
/// different ids), 1..200, not held by any other process using this function.
inline uint32_t UniqueDomain(uint32_t key) {
  static std::mutex mu;
  static std::map<uint32_t, uint32_t> given;  // key -> domain
  static std::set<uint32_t> held;
  std::lock_guard<std::mutex> lock(mu);
  if (auto it = given.find(key); it != given.end()) return it->second;
  const std::string dir = "/tmp/poseforest-test-domains";
  ::mkdir(dir.c_str(), 0777);
  ::chmod(dir.c_str(), 0777);  // shared by users running tests on one machine
  const uint32_t start = (uint32_t(::getpid()) * 13 + key * 31) % 200;
  for (uint32_t k = 0; k < 200; ++k) {
    const uint32_t domain = 1 + (start + k) % 200;
    if (held.count(domain)) continue;
    const std::string path = dir + "/" + std::to_string(domain) + ".lock";
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd < 0) continue;
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      ::close(fd);
      continue;
    }
    // fd stays open (and locked) for the life of the process.
    held.insert(domain);
    given[key] = domain;
    return domain;
  }
  // Every id held (200 parallel users of DDS tests): fall back to the pid-based one.
  given[key] = 1 + start;
  return 1 + start;
}

}  // namespace poseforest::testing
