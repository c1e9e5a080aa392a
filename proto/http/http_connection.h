#pragma once
// One connection of the HTTP server (http_server.cpp): its socket and TLS session under one
// deadline, the stream cpp-httplib reads and writes through, the thread per connection, and the
// steps before httplib (TLS handshake, request head). Internal to proto/http.

#include <arpa/inet.h>
#include <netinet/in.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <system_error>
#include <thread>

// cpp-httplib with its OpenSSL support (CPPHTTPLIB_OPENSSL_SUPPORT comes with the pkg-config target).
#include <httplib.h>

#include "proto/http/http_tls.h"

namespace poseforest::proto::http::detail {

using Clock = std::chrono::steady_clock;

/// One connection's socket (and TLS session) under one deadline for the whole exchange: the
/// request head in, the reply out. httplib's own timeouts are per read and per write, so a client
/// that sends a byte now and then (slow loris) would hold a connection forever; every wait here
/// ends at the deadline, or at once when the server stops.
struct Conn {
  int fd = -1;
  int wake_fd = -1;  ///< readable once the server stops
  SslPtr ssl;
  Clock::time_point deadline;
  bool timed_out = false;  ///< the last wait ended at the deadline (not at a stop)

  Conn() = default;
  Conn(const Conn&) = delete;
  Conn& operator=(const Conn&) = delete;
  ~Conn() {
    if (fd >= 0) Close();
  }

  /// Until `fd` is ready for `events`; false at the deadline or when the server stops.
  bool Wait(short events) {
    for (;;) {
      const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - Clock::now()).count();
      if (left <= 0) {
        timed_out = true;
        return false;
      }
      pollfd p[2] = {{fd, events, 0}, {wake_fd, POLLIN, 0}};
      const int r = ::poll(p, 2, int(std::min<int64_t>(left, 1000)));
      if (r < 0 && errno != EINTR) return false;
      if (r > 0 && (p[1].revents & POLLIN)) return false;
      if (r > 0 && p[0].revents != 0) return true;
    }
  }
  /// Waits for what an SSL_* call that returned `r` <= 0 needs; false: it failed, or the wait did.
  bool SslWait(int r) {
    const int e = SSL_get_error(ssl.get(), r);
    if (e == SSL_ERROR_WANT_READ) return Wait(POLLIN);
    if (e == SSL_ERROR_WANT_WRITE) return Wait(POLLOUT);
    return false;
  }
  /// Some bytes (> 0), 0 when the peer closed, -1 on an error or a failed wait.
  ssize_t Read(char* buf, size_t size) {
    for (;;) {
      if (ssl) {
        ERR_clear_error();
        const int r = SSL_read(ssl.get(), buf, int(std::min<size_t>(size, 1 << 20)));
        if (r > 0) return r;
        if (SSL_get_error(ssl.get(), r) == SSL_ERROR_ZERO_RETURN) return 0;
        if (!SslWait(r)) return -1;
        continue;
      }
      const ssize_t n = ::recv(fd, buf, size, MSG_DONTWAIT);
      if (n >= 0) return n;
      if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) return -1;
      if (!Wait(POLLIN)) return -1;
    }
  }
  /// All of `size` bytes, or false.
  bool WriteAll(const char* data, size_t size) {
    size_t sent = 0;
    while (sent < size) {
      if (ssl) {
        ERR_clear_error();
        const int r = SSL_write(ssl.get(), data + sent, int(std::min<size_t>(size - sent, 1 << 20)));
        if (r > 0) {
          sent += size_t(r);
        } else if (!SslWait(r)) {
          return false;
        }
        continue;
      }
      const ssize_t n = ::send(fd, data + sent, size - sent, MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n > 0) {
        sent += size_t(n);
      } else if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
        return false;
      } else if (!Wait(POLLOUT)) {
        return false;
      }
    }
    return true;
  }
  /// Ends the connection: TLS close_notify (so that the client knows the reply is complete), what
  /// already arrived read and dropped (so that close() sends FIN, not an RST that would discard the
  /// reply at the client), FIN, close.
  void Close() {
    if (ssl) {
      ERR_clear_error();
      (void)SSL_shutdown(ssl.get());
      ERR_clear_error();
      ssl.reset();
    }
    char sink[4096];
    while (::recv(fd, sink, sizeof sink, MSG_DONTWAIT) > 0) {
    }
    ::shutdown(fd, SHUT_WR);
    ::close(fd);
    fd = -1;
  }
};

/// httplib reads the request from, and writes the reply to, a Conn through this: the request head
/// that the checks before httplib already read first, then the socket.
class ConnStream final : public httplib::Stream {
 public:
  ConnStream(Conn* c, std::string head, std::string peer_ip, int peer_port)
      : c_(c), head_(std::move(head)), peer_ip_(std::move(peer_ip)), peer_port_(peer_port) {}
  bool is_readable() const override {
    return pos_ < head_.size() || (c_->ssl && SSL_pending(c_->ssl.get()) > 0) || c_->Wait(POLLIN);
  }
  bool is_writable() const override { return c_->Wait(POLLOUT); }
  ssize_t read(char* ptr, size_t size) override {
    if (pos_ < head_.size()) {
      const size_t n = std::min(size, head_.size() - pos_);
      std::memcpy(ptr, head_.data() + pos_, n);
      pos_ += n;
      return ssize_t(n);
    }
    return c_->Read(ptr, size);
  }
  ssize_t write(const char* ptr, size_t size) override {
    return c_->WriteAll(ptr, size) ? ssize_t(size) : -1;
  }
  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    ip = peer_ip_;
    port = peer_port_;
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    sockaddr_in a{};
    socklen_t len = sizeof a;
    char text[INET_ADDRSTRLEN] = "";
    if (::getsockname(c_->fd, reinterpret_cast<sockaddr*>(&a), &len) == 0)
      ::inet_ntop(AF_INET, &a.sin_addr, text, sizeof text);
    ip = text;
    port = ntohs(a.sin_port);
  }
  socket_t socket() const override { return c_->fd; }

 private:
  Conn* c_;
  std::string head_;
  size_t pos_ = 0;
  std::string peer_ip_;
  int peer_port_;
};

/// httplib's task queue with a thread per connection, where its default is a fixed pool (8
/// threads) that queues the rest: with a pool, idle or slow clients would keep the next ones
/// waiting, unseen, until a thread is free, while the caps (HttpServer::Serve) must look at every
/// connection as soon as it is accepted and refuse the extra ones at once. The threads are
/// short-lived (the deadline bounds each) and joined.
class ThreadPerConnection final : public httplib::TaskQueue {
 public:
  void enqueue(std::function<void()> fn) override {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto it = threads_.begin(); it != threads_.end();) {
      if (*it->done) {
        it->thread.join();
        it = threads_.erase(it);
      } else {
        ++it;
      }
    }
    auto done = std::make_shared<std::atomic<bool>>(false);
    auto task = std::make_shared<std::function<void()>>(std::move(fn));
    try {
      threads_.push_back({std::thread([task, done] {
                            (*task)();
                            *done = true;
                          }),
                          done});
    } catch (const std::system_error&) {
      // No thread to be had: served here, holding up the accept loop for one connection.
      (*task)();
    }
  }
  void shutdown() override {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto& t : threads_) t.thread.join();
    threads_.clear();
  }

 private:
  struct Worker {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> done;
  };
  std::mutex mu_;
  std::list<Worker> threads_;
};

/// Prepares an accepted socket (close-on-exec, non-blocking, SIGPIPE blocked on this thread) and
/// says who is at the other end: its address into `peer`, "IP:PORT" returned, the IP text into `ip`.
std::string PreparePeer(int fd, sockaddr_in* peer, char (&ip)[INET_ADDRSTRLEN]);

/// How a TLS handshake (TlsAccept) ended.
struct Handshake {
  enum Outcome { kDone, kNoSession, kWaitEnded, kFailed } outcome = kDone;
  bool plain_http = false;    ///< kFailed: plain HTTP sent to the HTTPS port
  bool sent_nothing = false;  ///< kFailed: the peer sent no byte (a port check)
  std::string why;            ///< kFailed: OpenSSL's reasons
};


/// The TLS handshake of `c` (on `fd`) under the connection's deadline (httplib's SSLServer
/// cannot say why one failed, nor answer plain HTTP sent to the port). Unless kDone, c.ssl is
/// reset and the connection is left to be closed.
Handshake TlsAccept(Conn& c, SSL_CTX* ctx, int fd);

/// How reading a request head (ReadHead) ended.
enum class HeadRead { kOk, kTlsOnPlainPort, kTooLarge, kTimedOut, kGone };

/// The request head, read here rather than by httplib: bounded in size (431; httplib's limits are
/// per line, 8 KiB) and in time (408 at the deadline, for the whole head). kOk: the head is
/// in[0, *end).
HeadRead ReadHead(Conn& c, size_t max_head_bytes, std::string& in, size_t* end_out);

/// The head with CRLF line ends (httplib wants them; the checks before it also took bare LF
/// ones) and the blank line after it.
std::string CrlfHead(const std::string& in, size_t end);

}  // namespace poseforest::proto::http::detail
