#pragma once
// A small dependency-free HTTP/1.1 server for the coordinator's status (GET/HEAD only, one
// response per connection, "Connection: close"), and the matching client used by
// `poseforest monitor`. One background thread polls every socket without blocking, so a slow or
// hostile client cannot hold up the others or the training thread: request heads are bounded
// (431), malformed request lines get 400, other methods 405, a request not complete within the
// timeout 408, and connections beyond the limit are closed at once. docs/distributed/monitoring.md.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "runtime/core/result.h"

namespace poseforest::dist {

struct HttpRequest {
  std::string method;  ///< GET or HEAD
  std::string path;    ///< without the query, e.g. "/status.json"
  std::string query;   ///< after '?', may be empty
};

struct HttpResponse {
  int status = 200;
  std::string content_type = "text/plain; charset=utf-8";
  std::string body;
};

struct HttpServerOptions {
  std::string address = "127.0.0.1";        ///< IPv4 literal to bind ("0.0.0.0": every interface)
  uint16_t port = 0;                        ///< 0: any free port (see HttpServer::port())
  size_t max_head_bytes = 16 * 1024;        ///< request line + headers; larger: 431
  int max_connections = 64;                 ///< more at once are closed right away
  std::chrono::milliseconds timeout{5000};  ///< to receive the request head and send the reply
};

/// "HOST:PORT" (HOST an IPv4 literal or "localhost", PORT 0..65535) into `opt`.
core::Status ParseHttpAddress(const std::string& text, HttpServerOptions* opt);

class HttpServer {
 public:
  using Handler = std::function<HttpResponse(const HttpRequest&)>;

  /// Binds, listens and starts the serving thread. Errors name the address.
  static core::Result<std::unique_ptr<HttpServer>> Start(const HttpServerOptions& opt, Handler handler);
  ~HttpServer();  ///< stops the thread and closes every socket

  uint16_t port() const { return port_; }
  /// "http://ADDRESS:PORT" (0.0.0.0 shown as 127.0.0.1).
  std::string url() const;

  uint64_t requests() const { return requests_; }  ///< answered with the handler
  uint64_t bad_requests() const { return bad_; }   ///< answered 400/405/408/431
  uint64_t dropped() const { return dropped_; }    ///< closed over the connection limit

 private:
  HttpServer() = default;
  void Loop();

  HttpServerOptions opt_;
  Handler handler_;
  int listen_fd_ = -1, wake_[2] = {-1, -1};
  uint16_t port_ = 0;
  std::atomic<bool> stop_{false};
  std::atomic<uint64_t> requests_{0}, bad_{0}, dropped_{0};
  std::thread thread_;
};

/// The body of GET http://HOST:PORT/path ("http://" URLs only, IPv4 or localhost). Errors: the
/// URL, connection, timeout, a non-200 status (its code and first line of the body).
core::Result<std::string> HttpGet(const std::string& url, std::chrono::milliseconds timeout);

}  // namespace poseforest::dist
