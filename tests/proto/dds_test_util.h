#pragma once
// Helpers of the DDS tests: unique domain ids, building valid envelopes, and running the
// poseforest_dds_peer helper as a real child process (posix_spawn) with its stdout on a pipe.

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "poseforest/v1/wire.pb.h"
#include "proto/dds/histogram_codec.h"
#include "proto/dds/message_gate.h"
#include "runtime/core/crc32.h"
#include "tests/support/dds_domain.h"

extern char** environ;

namespace poseforest::proto::dds::testing {

/// A domain no parallel test process uses (tests/support/dds_domain.h); the same `offset` gives
/// the same domain within a process. (Keys 1000+: apart from the distributed tests' Domain().)
inline uint32_t TestDomain(uint32_t offset = 0) { return poseforest::testing::UniqueDomain(1000 + offset); }

/// The folder of the built test programs and helpers.
inline std::filesystem::path HelperDir() {
  if (const char* env = std::getenv("POSEFOREST_BIN_DIR"); env && *env) return env;
  return std::filesystem::read_symlink("/proc/self/exe").parent_path();
}
inline std::string PeerBinary() { return (HelperDir() / "poseforest_dds_peer").string(); }

/// A valid SubtreeResult body of about `bytes` bytes (pseudo-random nodes keyed by `seed`, CRC set):
/// the gate's CRC check then verifies the payload arrived intact.
inline poseforest::v1::SubtreeResult BigSubtree(size_t bytes, uint32_t seed) {
  poseforest::v1::SubtreeResult r;
  const uint32_t nodes = uint32_t(bytes / 16) + 1;
  std::string data(size_t(nodes) * 16, '\0');
  uint64_t x = 0x9E3779B97F4A7C15ull * (seed + 1);
  for (size_t i = 0; i < data.size(); ++i) {
    x ^= x << 13, x ^= x >> 7, x ^= x << 17;
    data[i] = char(x);
  }
  r.set_tree(0);
  r.set_node_id(seed);
  r.set_epoch(1);
  r.set_num_nodes(nodes);
  r.set_num_leaves(1);
  r.set_num_parts(31);
  r.set_nodes(std::move(data));
  r.set_leaves(std::string(32, '\x07'));
  uint32_t crc = core::Crc32(r.nodes().data(), r.nodes().size());
  r.set_crc32(core::Crc32(r.leaves().data(), r.leaves().size(), crc));
  return r;
}

inline poseforest::v1::WorkerCapacity Capacity(uint32_t threads = 4) {
  poseforest::v1::WorkerCapacity c;
  c.set_threads(threads);
  c.set_memory_mb(1024);
  c.set_renderer(poseforest::v1::RENDERER_KIND_PROCEDURAL);
  return c;
}

/// A child process with stdout (and stderr) readable line by line.
class Child {
 public:
  Child() = default;
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  ~Child() { Kill(SIGKILL); }

  /// Starts argv[0] with argv; false (and errno text in `error`) on failure.
  bool Start(const std::vector<std::string>& argv, std::string* error) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) {
      *error = "pipe failed";
      return false;
    }
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, fds[1], 1);
    posix_spawn_file_actions_adddup2(&actions, fds[1], 2);
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    const int rc = ::posix_spawnp(&pid_, args[0], &actions, nullptr, args.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    ::close(fds[1]);
    if (rc != 0) {
      ::close(fds[0]);
      *error = "cannot start " + argv[0] + ": " + std::strerror(rc);
      pid_ = -1;
      return false;
    }
    out_fd_ = fds[0];
    return true;
  }

  /// Next output line, waiting up to `timeout`; nullopt on timeout or EOF.
  std::optional<std::string> ReadLine(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      if (auto nl = buffer_.find('\n'); nl != std::string::npos) {
        std::string line = buffer_.substr(0, nl);
        buffer_.erase(0, nl + 1);
        output_ += line + "\n";
        return line;
      }
      if (out_fd_ < 0) return std::nullopt;
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return std::nullopt;
      pollfd p{out_fd_, POLLIN, 0};
      if (::poll(&p, 1, int(left.count())) <= 0) continue;
      char buf[4096];
      const ssize_t n = ::read(out_fd_, buf, sizeof buf);
      if (n <= 0) {
        ::close(out_fd_);
        out_fd_ = -1;
        continue;
      }
      buffer_.append(buf, size_t(n));
    }
  }

  /// Reads lines until one contains `needle`; returns it, or nullopt on timeout/EOF.
  std::optional<std::string> WaitForLine(const std::string& needle, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return std::nullopt;
      auto line = ReadLine(left);
      if (!line) return std::nullopt;
      if (line->find(needle) != std::string::npos) return line;
    }
  }

  /// Waits for exit up to `timeout`; returns the exit status (or -signal), nullopt on timeout.
  std::optional<int> Wait(std::chrono::milliseconds timeout) {
    if (pid_ <= 0) return exit_;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      int status = 0;
      const pid_t r = ::waitpid(pid_, &status, WNOHANG);
      if (r == pid_) {
        pid_ = -1;
        exit_ = WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
        DrainOutput();
        return exit_;
      }
      if (std::chrono::steady_clock::now() >= deadline) return std::nullopt;
      ReadLine(std::chrono::milliseconds(20));  // keep the pipe from filling up
    }
  }

  void Kill(int sig) {
    if (pid_ > 0) {
      ::kill(pid_, sig);
      if (sig == SIGKILL) {
        int status = 0;
        ::waitpid(pid_, &status, 0);
        exit_ = -SIGKILL;
        pid_ = -1;
      }
    }
    if (out_fd_ >= 0 && pid_ < 0) DrainOutput();
  }

  pid_t pid() const { return pid_; }
  /// Every line read so far (for failure messages).
  const std::string& output() const { return output_; }
  /// Reads what a running child has written by now (until it is quiet for 20 ms), then every
  /// line so far: for failure messages about children still running.
  const std::string& OutputNow() {
    // 20 ms, not 1: ReadLine rounds what is left of its timeout down to whole milliseconds, and
    // with 1 ms it returned before reading anything (the workers' output in the --resume test's
    // failure message was always empty).
    while (ReadLine(std::chrono::milliseconds(20))) {
    }
    return output_;
  }

 private:
  void DrainOutput() {
    while (out_fd_ >= 0 && ReadLine(std::chrono::milliseconds(200))) {
    }
  }
  pid_t pid_ = -1;
  int out_fd_ = -1;
  std::optional<int> exit_;
  std::string buffer_, output_;
};

}  // namespace poseforest::proto::dds::testing
