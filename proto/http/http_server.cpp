#include "proto/http/http_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <list>
#include <set>
#include <system_error>
#include <vector>

// cpp-httplib with its OpenSSL support (CPPHTTPLIB_OPENSSL_SUPPORT comes with the pkg-config target).
#include <httplib.h>

#include "proto/http/http_connection.h"
#include "proto/http/http_request.h"
#include "proto/http/http_tls.h"

// The server: a connection's checks before cpp-httplib (caps, deadline, TLS handshake, request
// head, token), then httplib's request processing. The request checks are in http_request.cpp,
// the TLS files and context in http_tls.cpp, the client in http_client.cpp.

namespace poseforest::proto::http {

using core::ErrorCode;
using core::Result;
using core::Status;
using detail::Conn;
using detail::ConnStream;
using detail::CrlfHead;
using detail::Error;
using detail::Handshake;
using detail::HeadRead;
using detail::MakeServerContext;
using detail::OpenSslReasons;
using detail::ParseHead;
using detail::PreparePeer;
using detail::PresentedToken;
using detail::ReadHead;
using detail::Serialize;
using detail::SslCtxPtr;
using detail::SslPtr;
using detail::ThreadPerConnection;
using detail::TlsAccept;

using detail::Clock;

void HttpServer::Log(const std::string& line) {
  if (!opt_.log) return;
  std::lock_guard<std::mutex> lock(log_mu_);  // connections log from their own threads
  const auto now = Clock::now();
  if (log_refill_ == Clock::time_point{}) {
    log_credit_ = std::max(1, opt_.log_burst);
    log_refill_ = now;
  }
  // One more line allowed per interval, up to the burst.
  if (opt_.log_interval.count() > 0) {
    const auto gained = (now - log_refill_) / opt_.log_interval;
    if (gained > 0) {
      log_credit_ = int(std::min<int64_t>(std::max(1, opt_.log_burst), log_credit_ + int64_t(gained)));
      log_refill_ += opt_.log_interval * gained;
    }
  }
  if (log_credit_ <= 0) {
    ++log_suppressed_;
    return;
  }
  --log_credit_;
  std::string l = line;
  if (log_suppressed_ > 0) l += " (" + std::to_string(log_suppressed_) + " more refused requests not logged)";
  log_suppressed_ = 0;
  try {
    opt_.log(l);
  } catch (...) {
  }
}

struct HttpServer::Tls {
  SslCtxPtr ctx;
};

namespace {

/// The request being served on this thread (set by HttpServer::Serve around httplib's processing,
/// read by the route): the request line as the checks before httplib parsed it, the peer, the server.
thread_local const HttpRequest* g_current_request = nullptr;

}  // namespace

/// The httplib::Server that answers a connection once the checks around it have passed.
/// process_and_close_socket is httplib's hook for one accepted socket (its SSLServer overrides it
/// the same way to add TLS); ours hands the socket to HttpServer::Serve, which calls back Process.
class HttpServer::Httpd final : public httplib::Server {
 public:
  explicit Httpd(HttpServer* owner) : owner_(owner) {}
  /// httplib parses the request in `strm`, routes it and writes the reply ("Connection: close").
  bool Process(httplib::Stream& strm, const HttpRequest& req) {
    g_current_request = &req;
    bool closed = false;
    const bool ok = process_request(strm, /*close_connection=*/true, closed, nullptr);
    g_current_request = nullptr;
    return ok;
  }
  /// httplib 0.11 listens with a backlog of 5 (CPPHTTPLIB_LISTEN_BACKLOG, compiled into Debian's
  /// library): a burst of connections beyond it would wait for the kernel's SYN-ACK retries (a
  /// second or more), long enough to miss the caps or the timeout. Linux takes a second listen()
  /// on the bound socket as a new backlog.
  bool SetBacklog(int backlog) { return ::listen(svr_sock_, backlog) == 0; }

 private:
  bool process_and_close_socket(socket_t sock) override {
    owner_->Serve(sock);
    return true;
  }
  HttpServer* owner_;
};

struct HttpServer::Peers {
  std::mutex mu;
  std::multiset<uint32_t> open;  ///< one entry per open connection: its peer's IPv4 address
};

Result<std::unique_ptr<HttpServer>> HttpServer::Start(const HttpServerOptions& opt, Handler handler) {
  std::unique_ptr<HttpServer> s(new HttpServer());
  s->opt_ = opt;
  s->handler_ = std::move(handler);
  if (!opt.tls_cert_file.empty() || !opt.tls_key_file.empty()) {
    auto ctx = MakeServerContext(opt.tls_cert_file, opt.tls_key_file);
    if (!ctx.ok()) return ctx.status();
    s->tls_ = std::make_shared<Tls>();
    s->tls_->ctx = std::move(*ctx);
  }
  const std::string where = opt.address + ":" + std::to_string(opt.port);
  in_addr check{};
  if (::inet_pton(AF_INET, opt.address.c_str(), &check) != 1)
    return Status(ErrorCode::kInvalidArgument, "HTTP address " + where + ": not an IPv4 address");
  if (::pipe2(s->wake_, O_CLOEXEC | O_NONBLOCK) != 0)
    return Status(ErrorCode::kIo, "HTTP pipe: " + std::string(std::strerror(errno)));
  s->peers_ = std::make_unique<Peers>();
  s->httpd_ = std::make_unique<Httpd>(s.get());
  Httpd& h = *s->httpd_;
  h.new_task_queue = [] { return new ThreadPerConnection(); };
  // httplib's default sets SO_REUSEPORT, which would let a second server bind the same port.
  h.set_socket_options([](socket_t sock) {
    const int one = 1;
    ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    ::fcntl(sock, F_SETFD, FD_CLOEXEC);
  });
  h.set_address_family(AF_INET);
  h.set_default_headers({{"Cache-Control", "no-store"},
                         {"X-Content-Type-Options", "nosniff"},
                         {"Referrer-Policy", "no-referrer"}});
  HttpServer* raw = s.get();
  // Every request that reaches httplib was checked (method GET or HEAD, target, token): one route.
  h.Get(".*", [raw](const httplib::Request&, httplib::Response& res) {
    HttpResponse r;
    try {
      r = raw->handler_(*g_current_request);
    } catch (...) {
      r = Error(500, "handler failed");
    }
    ++raw->requests_;
    res.status = r.status;
    res.set_content(r.body, r.content_type.c_str());
  });
  errno = 0;
  // Port 0: the one the kernel chose (bind_to_any_port says it).
  const int port = opt.port == 0 ? h.bind_to_any_port(opt.address)
                                 : (h.bind_to_port(opt.address, opt.port) ? opt.port : -1);
  if (port < 0)
    return Status(ErrorCode::kIo,
                  "HTTP bind " + where + ": " + (errno != 0 ? std::strerror(errno) : "cannot listen there"));
  s->port_ = uint16_t(port);
  if (!h.SetBacklog(std::max(64, opt.max_connections)))
    return Status(ErrorCode::kIo, "HTTP listen " + where + ": " + std::strerror(errno));
  s->thread_ = std::thread([raw] { raw->httpd_->listen_after_bind(); });
  // Until the accept loop runs: Server::stop() before that would leave it running forever.
  for (int i = 0; i < 10000 && !h.is_running(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  return s;
}

HttpServer::~HttpServer() {
  if (wake_[1] >= 0) {
    const char c = 1;
    (void)!::write(wake_[1], &c, 1);  // every connection's wait ends
  }
  if (httpd_) httpd_->stop();  // the accept loop ends, then httplib joins the connections' threads
  if (thread_.joinable()) thread_.join();
  for (int fd : wake_)
    if (fd >= 0) ::close(fd);
}

std::string HttpServer::url() const {
  const std::string host = opt_.address == "0.0.0.0" ? "127.0.0.1" : opt_.address;
  return (tls_ ? "https://" : "http://") + host + ":" + std::to_string(port_);
}

bool HttpServer::Admit(int fd, uint32_t ip, const std::string& peer_text) {
  // The connection caps (in all, and per peer address), which httplib does not have: checked as
  // soon as the connection is accepted (a thread per connection, see ThreadPerConnection).
  std::unique_lock<std::mutex> lock(peers_->mu);
  const int from_peer = int(peers_->open.count(ip));
  const bool over_total = int(peers_->open.size()) >= opt_.max_connections;
  const bool over_peer = from_peer >= opt_.max_connections_per_peer;
  if (over_total || over_peer) {
    lock.unlock();
    ++dropped_;
    if (over_peer)
      Log("http: 503 for a connection from " + peer_text + ": " + std::to_string(from_peer) +
          " already open from that address");
    // Plain HTTP: a 503. TLS: just closed (before a handshake there is no way to say it).
    if (!tls_) {
      const std::string r = Serialize(Error(503, "too many connections"), false);
      (void)::send(fd, r.data(), r.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    }
    return false;
  }
  peers_->open.insert(ip);
  return true;
}

void HttpServer::Serve(int fd) {
  sockaddr_in peer{};
  char ip[INET_ADDRSTRLEN] = "?";
  const std::string peer_text = PreparePeer(fd, &peer, ip);
  Conn c;
  c.fd = fd;
  c.wake_fd = wake_[0];
  c.deadline = Clock::now() + opt_.timeout;

  if (!Admit(fd, peer.sin_addr.s_addr, peer_text)) {
    c.Close();
    return;
  }
  struct Leave {
    Peers* peers;
    uint32_t ip;
    ~Leave() {
      std::lock_guard<std::mutex> lock(peers->mu);
      peers->open.erase(peers->open.find(ip));
    }
  } leave{peers_.get(), peer.sin_addr.s_addr};

  auto respond = [&](const HttpResponse& r, bool head_only, const std::string& extra_headers = "") {
    const std::string bytes = Serialize(r, head_only, extra_headers);
    (void)c.WriteAll(bytes.data(), bytes.size());
    c.Close();
  };

  if (tls_) {
    const Handshake hs = TlsAccept(c, tls_->ctx.get(), fd);
    if (hs.outcome != Handshake::kDone) {
      if (hs.outcome == Handshake::kNoSession) ++dropped_;
      if (hs.outcome == Handshake::kWaitEnded && c.timed_out) ++bad_;  // a silent or slow client
      if (hs.outcome == Handshake::kFailed && !hs.sent_nothing) {
        ++tls_failed_;
        Log("http: TLS handshake with " + peer_text +
            " failed: " + (hs.plain_http ? std::string("plain HTTP sent to the HTTPS port") : hs.why));
        if (hs.plain_http) {
          const std::string bytes =
              Serialize(Error(400, "this port speaks HTTPS only: use https:// instead of http://"), false);
          (void)::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
        }
      }
      c.Close();
      return;
    }
  }

  std::string in;
  size_t end = std::string::npos;
  switch (ReadHead(c, opt_.max_head_bytes, in, &end)) {
    case HeadRead::kOk:
      break;
    case HeadRead::kTlsOnPlainPort:
      ++bad_;
      respond(Error(400, "this port speaks plain HTTP, not TLS: use http://"), false);
      return;
    case HeadRead::kTooLarge:
      ++bad_;
      respond(Error(431, "request head over " + std::to_string(opt_.max_head_bytes) + " bytes"), false);
      return;
    case HeadRead::kTimedOut:
      // Slow client: one best-effort 408, then close.
      ++bad_;
      c.deadline = Clock::now() + std::chrono::milliseconds(100);
      respond(Error(408, "request not complete in time"), false);
      return;
    case HeadRead::kGone:
      c.Close();
      return;
  }

  // The request line, checked more strictly than httplib does (which takes "GET  /  HTTP/1.1",
  // "GET nopath ...", and answers other methods 400 or 404 rather than 405).
  HttpRequest req;
  HttpResponse err;
  if (!ParseHead(in.substr(0, end), &req, &err)) {
    ++bad_;
    respond(err, false);
    return;
  }
  req.peer = peer_text;
  req.server = this;

  // The bearer token, checked on the raw head: httplib 0.11 percent-decodes header values, and its
  // query parser turns '+' into a space.
  bool present = false, ambiguous = false;
  // /healthz is open (probes carry no secret; its "ok" reveals nothing).
  const bool authorized =
      opt_.bearer_token.empty() || req.path == "/healthz" ||
      (ConstantTimeEquals(PresentedToken(in.substr(0, end), req, &present, &ambiguous), opt_.bearer_token) &&
       !ambiguous);
  if (!authorized) {
    // Nothing about the server or the path: the status, the scheme, one line.
    ++unauthorized_;
    Log("http: 401 for " + req.method + " " + req.path.substr(0, 100) + " from " + peer_text + ": " +
        (ambiguous ? "several Authorization headers"
         : present ? "wrong token"
                   : "no token"));
    respond({401, "text/plain; charset=utf-8", "401 Unauthorized: a bearer token is required\n"},
            req.method == "HEAD",
            std::string("WWW-Authenticate: Bearer realm=\"poseforest\"") +
                (present ? ", error=\"invalid_token\"" : "") + "\r\n");
    return;
  }
  // httplib: the headers, the route, the reply.
  ConnStream strm(&c, CrlfHead(in, end), ip, ntohs(peer.sin_port));
  (void)httpd_->Process(strm, req);
  c.Close();
}

}  // namespace poseforest::proto::http
