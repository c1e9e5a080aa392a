#pragma once
// The coordinator's HTTP status server from the outside, for test_monitoring and test_http_auth:
// raw requests on a socket, and the web dashboard as a browser shows it (headless Chromium,
// Debian `chromium`, installed by scripts/setup.sh: it loads a page, runs its script, dumps the
// DOM).

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

#include "tests/coordinator/dist_test_util.h"
#include "tests/support/process.h"

namespace poseforest::coordinator::testing {

/// Collects the lines a server logs (HttpServerOptions::log; called on the serving thread).
class LogLines {
 public:
  std::function<void(const std::string&)> Sink() {
    return [this](const std::string& line) {
      std::lock_guard<std::mutex> lock(mu_);
      lines_.push_back(line);
    };
  }
  /// A copy of the lines so far.
  std::vector<std::string> Lines() const {
    std::lock_guard<std::mutex> lock(mu_);
    return lines_;
  }
  /// The lines so far, one per line (for INFO).
  std::string Joined() const {
    std::string all;
    for (const auto& l : Lines()) all += l + "\n";
    return all;
  }

 private:
  mutable std::mutex mu_;
  std::vector<std::string> lines_;
};

/// A connected socket to 127.0.0.1:`port` (from `source`, a loopback address, when given).
inline int ConnectLoopback(uint16_t port, const char* source = nullptr) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  REQUIRE(fd >= 0);
  if (source) {
    sockaddr_in s{};
    s.sin_family = AF_INET;
    REQUIRE(::inet_pton(AF_INET, source, &s.sin_addr) == 1);
    REQUIRE(::bind(fd, reinterpret_cast<sockaddr*>(&s), sizeof s) == 0);
  }
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  REQUIRE(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
  return fd;
}

/// What came back on a raw connection, and who ended it.
struct Exchange {
  std::string bytes;            ///< everything received
  bool closed_by_peer = false;  ///< the server closed (or reset) the connection; false: `timeout` ran out
};

/// Sends `bytes` on a fresh connection to 127.0.0.1:`port` (from `source`, a loopback address,
/// when given) and reads until the server closes or `timeout` runs out. A test that gives the
/// client a shorter timeout than the server's own learns from `closed_by_peer` that the server
/// closed for a reason of its own, not at its timeout, without measuring time.
inline Exchange RawExchangeUntilClosed(uint16_t port, const std::string& bytes,
                                       std::chrono::milliseconds timeout = std::chrono::seconds(5),
                                       const char* source = nullptr) {
  const int fd = ConnectLoopback(port, source);
  size_t sent = 0;
  while (sent < bytes.size()) {
    const ssize_t n = ::send(fd, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) break;  // the server may close early (431, 401): fine
    sent += size_t(n);
  }
  Exchange out;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) break;
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, int(left.count())) <= 0) break;
    char buf[4096];
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) {
      out.closed_by_peer = true;
      break;
    }
    out.bytes.append(buf, size_t(n));
  }
  ::close(fd);
  return out;
}

/// RawExchangeUntilClosed's bytes.
inline std::string RawExchange(uint16_t port, const std::string& bytes,
                               std::chrono::milliseconds timeout = std::chrono::seconds(5),
                               const char* source = nullptr) {
  return RawExchangeUntilClosed(port, bytes, timeout, source).bytes;
}

/// The status code of an HTTP/1.1 reply, -1 if it is not one.
inline int StatusCode(const std::string& reply) {
  if (reply.rfind("HTTP/1.1 ", 0) != 0 || reply.size() < 12) return -1;
  return std::atoi(reply.substr(9, 3).c_str());
}

/// The DOM of `url` (quoted for the shell) after its script has run for 4 s of virtual time;
/// `flags`: more Chromium flags (e.g. --ignore-certificate-errors-spki-list=HASH for an HTTPS test
/// server).
inline std::string DumpDom(const std::string& url, const std::string& flags = "") {
  REQUIRE(std::filesystem::exists("/usr/bin/chromium"));  // scripts/setup.sh installs it
  TempDir profile("pf-chromium-profile");
  const std::string cmd =
      "timeout 90 /usr/bin/chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run "
      "--disable-background-networking --disable-component-update --disable-sync --disable-dev-shm-usage "
      "--user-data-dir=" +
      profile.path.string() + " " + flags + " --virtual-time-budget=4000 --dump-dom '" + url +
      "' 2>/dev/null";
  auto r = poseforest::testing::RunCommand(cmd);
  INFO(r.output.substr(0, 3000));
  REQUIRE(r.exit_code == 0);
  return r.output;
}

/// Text content of the element with `id` in a dumped DOM (flat elements only).
inline std::string ElementText(const std::string& dom, const std::string& id) {
  const size_t at = dom.find("id=\"" + id + "\"");
  if (at == std::string::npos) return "";
  const size_t open = dom.find('>', at);
  const size_t close = dom.find('<', open);
  return dom.substr(open + 1, close - open - 1);
}

}  // namespace poseforest::coordinator::testing
