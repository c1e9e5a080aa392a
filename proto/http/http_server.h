#pragma once
// The HTTP status server of the services (GET/HEAD only, one response per connection, "Connection:
// close") on cpp-httplib (Debian libcpp-httplib-dev): the coordinator's dashboard, /status.json and
// /metrics (coordinator/monitoring/), the worker's /metrics (worker/worker_metrics.h); and the
// matching client used by `poseforest monitor` (httplib::Client / SSLClient). Below both services
// (a target of its own, poseforest::http, that neither the engine nor the DDS transport links), so
// that they share it without including each other (docs/architecture.md). cpp-httplib parses the
// request, routes it to the handler and writes the response; what it does not do is done around
// it, before a request reaches it (http_server.cpp says why for each): connection caps (in all,
// and per peer address: 503), one deadline for the whole exchange (slow clients: 408), bounded
// request heads (431), strict request lines (400; other methods 405), the bearer token
// (`--http-token-file`: every request but /healthz must carry it, "Authorization: Bearer TOKEN",
// or `?token=TOKEN` for the dashboard page itself; others get 401, are counted and logged,
// rate-limited, with the peer address) and HTTPS (`--http-tls-cert`, `--http-tls-key`; OpenSSL,
// TLS 1.2+): a failed handshake is counted and logged, and plain HTTP sent to the TLS port gets a
// plain 400. docs/distributed/monitoring.md.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "runtime/core/result.h"

namespace poseforest::proto::http {

class HttpServer;

struct HttpRequest {
  std::string method;                  ///< GET or HEAD
  std::string path;                    ///< without the query, e.g. "/status.json"
  std::string query;                   ///< after '?', may be empty
  std::string peer;                    ///< the client's "IP:PORT"
  const HttpServer* server = nullptr;  ///< the server answering (its counters for /metrics)
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
  int max_connections_per_peer = 16;        ///< more at once from one IP address are closed right away
  /// Non-empty: every request needs "Authorization: Bearer <token>" (or, for "/" and
  /// "/index.html" only, the query parameter token=<token>); others get 401. Compared in constant
  /// time. See ReadHttpTokenFile. "/healthz" is answered without it (liveness and readiness probes;
  /// the handler's "ok" reveals nothing).
  std::string bearer_token;
  /// Receives a line per refused request (401, per-peer 503), at most `log_burst` lines at once
  /// and then one per `log_interval`, each saying how many were not logged. Null: no log.
  std::function<void(const std::string&)> log;
  int log_burst = 5;
  std::chrono::milliseconds log_interval{10000};
  /// Both non-empty: HTTPS only (TLS 1.2 or later) with this PEM certificate (chain: the server's
  /// certificate first) and PEM private key (unencrypted; checked like the token file: no access for
  /// others, nor for its group unless root owns it). Start() refuses a missing, unreadable or
  /// malformed file, or a key that does not match the certificate, naming the file.
  std::string tls_cert_file;
  std::string tls_key_file;
};

/// Loads `cert_file` and `key_file` as HttpServerOptions::tls_cert_file/tls_key_file would be
/// (for `--check-config`): InvalidArgument naming the flag and file on any problem.
core::Status CheckHttpTlsFiles(const std::string& cert_file, const std::string& key_file);

/// Checks that `ca_file` (`monitor --http-ca-file`) holds at least one PEM certificate:
/// InvalidArgument naming the file otherwise.
core::Status CheckHttpCaFile(const std::string& ca_file);

/// The bearer token in `path` (`--http-token-file`), checked like ssh checks a private key: the file
/// must exist, be a regular file, not be readable or writable by others, nor by its group unless
/// root owns it (a Kubernetes Secret mounted with fsGroup: root:GROUP 0440); one trailing newline
/// ("\n" or "\r\n") is dropped; the token must be 1..4096 visible ASCII characters. Errors name
/// the file and say what to do.
core::Result<std::string> ReadHttpTokenFile(const std::string& path);

/// True for 127.0.0.0/8 (an IPv4 literal as in HttpServerOptions::address).
bool IsLoopbackAddress(const std::string& ipv4);

/// Equal strings, in time that depends only on the length of `given` (never on where they differ).
bool ConstantTimeEquals(const std::string& given, const std::string& expected);

/// "HOST:PORT" (HOST an IPv4 literal, "localhost", or empty for every interface, 0.0.0.0, as in
/// ":9101"; PORT 0..65535) into `opt`. Errors name the flag: "--http TEXT: ...".
core::Status ParseHttpAddress(const std::string& text, HttpServerOptions* opt);

/// The start-up warnings a server on `opt` deserves (none on a loopback address): without a token,
/// anyone who reaches it reads `served` ("the job's status, metrics and dashboard"); with a token
/// but without TLS, the token and `exposed` ("the job's status") cross the network in clear text.
/// Each line starts "warning: --http `http` ..."; the caller prefixes its name.
std::vector<std::string> HttpExposureWarnings(const HttpServerOptions& opt, const std::string& http,
                                              const std::string& served, const std::string& exposed);

class HttpServer {
 public:
  using Handler = std::function<HttpResponse(const HttpRequest&)>;

  /// Binds, listens and starts httplib's accept loop on its own thread. Errors name the address.
  static core::Result<std::unique_ptr<HttpServer>> Start(const HttpServerOptions& opt, Handler handler);
  ~HttpServer();  ///< stops the thread and closes every socket

  uint16_t port() const { return port_; }
  /// "http://ADDRESS:PORT" or "https://ADDRESS:PORT" with TLS (0.0.0.0 shown as 127.0.0.1).
  std::string url() const;
  bool tls() const { return tls_ != nullptr; }

  uint64_t requests() const { return requests_; }          ///< answered with the handler
  uint64_t bad_requests() const { return bad_; }           ///< answered 400/405/408/431
  uint64_t dropped() const { return dropped_; }            ///< closed over the connection limits
  uint64_t unauthorized() const { return unauthorized_; }  ///< answered 401 (no or a wrong token)
  /// TLS connections whose handshake failed (plain HTTP to the port, no common version or cipher,
  /// garbage); a connection closed before sending a byte is not counted.
  uint64_t tls_handshake_failures() const { return tls_failed_; }

 private:
  class Httpd;   // the httplib::Server (http_server.cpp)
  struct Tls;    // OpenSSL's server context (http_server.cpp)
  struct Peers;  // open connections by peer address (http_server.cpp)
  HttpServer() = default;
  /// One accepted connection, on its own thread (httplib's task queue): caps, TLS, the checks
  /// httplib does not make, then httplib's request processing. Closes `fd`.
  void Serve(int fd);
  /// The connection caps (in all, and per peer address `ip`): true and counted as open from `ip`,
  /// or false (counted, logged, a 503 sent on plain HTTP) and `fd` is to be closed.
  bool Admit(int fd, uint32_t ip, const std::string& peer_text);
  void Log(const std::string& line);

  HttpServerOptions opt_;
  Handler handler_;
  uint16_t port_ = 0;
  std::atomic<uint64_t> requests_{0}, bad_{0}, dropped_{0}, unauthorized_{0}, tls_failed_{0};
  std::shared_ptr<Tls> tls_;
  std::unique_ptr<Peers> peers_;
  std::unique_ptr<Httpd> httpd_;
  int wake_[2] = {-1, -1};  ///< readable once the server stops: ends every connection's wait
  std::thread thread_;      ///< httplib's accept loop
  // Rate limit of opt_.log (under log_mu_: connections log from their own threads).
  std::mutex log_mu_;
  int log_credit_ = 0;
  std::chrono::steady_clock::time_point log_refill_{};
  uint64_t log_suppressed_ = 0;
};

/// The body of GET http[s]://HOST[:PORT]/path (HOST an IPv4 address or a name resolved to one;
/// PORT default 80 / 443), with "Authorization: Bearer <bearer_token>" when one is given. For
/// https:// the server's certificate must chain to `ca_file` (PEM; empty: the system's trust store)
/// and name HOST (DNS name or IP address), over TLS 1.2 or later. Errors: the URL, connection,
/// timeout, TLS (an untrusted certificate or one for another host, saying what to do), a truncated
/// reply, a non-200 status (its code and first line of the body; for 401 also whether a token was
/// sent). InvalidArgument: retrying will not help (bad URL, 401, TLS refused). httplib's client:
/// `timeout` bounds the connect, and each read and write (not their sum).
core::Result<std::string> HttpGet(const std::string& url, std::chrono::milliseconds timeout,
                                  const std::string& bearer_token = "", const std::string& ca_file = "");

/// OK when HttpGet would accept `url`'s form (scheme, host, port); nothing is connected to.
core::Status CheckHttpUrl(const std::string& url);

}  // namespace poseforest::proto::http
