#include "coordinator/distributed/http_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <map>
#include <sstream>
#include <vector>

namespace poseforest::dist {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace {
using Clock = std::chrono::steady_clock;

const char* Reason(int status) {
  switch (status) {
    case 200:
      return "OK";
    case 400:
      return "Bad Request";
    case 401:
      return "Unauthorized";
    case 404:
      return "Not Found";
    case 405:
      return "Method Not Allowed";
    case 408:
      return "Request Timeout";
    case 431:
      return "Request Header Fields Too Large";
    case 500:
      return "Internal Server Error";
    case 503:
      return "Service Unavailable";
    default:
      return "Unknown";
  }
}

std::string Serialize(const HttpResponse& r, bool head_only, const std::string& extra_headers = "") {
  std::string out = "HTTP/1.1 " + std::to_string(r.status) + " " + Reason(r.status) + "\r\n";
  out += "Content-Type: " + r.content_type + "\r\n";
  out += "Content-Length: " + std::to_string(r.body.size()) + "\r\n";
  out +=
      "Cache-Control: no-store\r\nConnection: close\r\nX-Content-Type-Options: nosniff\r\n"
      "Referrer-Policy: no-referrer\r\n" +
      extra_headers + "\r\n";
  if (!head_only) out += r.body;
  return out;
}

HttpResponse Error(int status, const std::string& why) {
  return {status, "text/plain; charset=utf-8",
          std::to_string(status) + " " + Reason(status) + ": " + why + "\n"};
}

bool SetNonBlocking(int fd) {
  const int flags = ::fcntl(fd, F_GETFL, 0);
  return flags >= 0 && ::fcntl(fd, F_SETFL, flags | O_NONBLOCK) == 0;
}

bool IsTokenChar(char c) {
  return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' || c == '_';
}

struct Conn {
  int fd = -1;
  uint32_t peer_ip = 0;  ///< network order
  std::string peer;      ///< "IP:PORT"
  std::string in, out;
  size_t sent = 0;
  bool responding = false;
  Clock::time_point deadline;
};

/// Parses the request head; on failure returns the error response.
bool ParseHead(const std::string& head, HttpRequest* req, HttpResponse* error) {
  const size_t eol = head.find_first_of("\r\n");
  const std::string line = head.substr(0, eol);
  const size_t sp1 = line.find(' ');
  const size_t sp2 = sp1 == std::string::npos ? std::string::npos : line.find(' ', sp1 + 1);
  if (sp1 == std::string::npos || sp2 == std::string::npos || line.find(' ', sp2 + 1) != std::string::npos) {
    *error = Error(400, "malformed request line");
    return false;
  }
  const std::string method = line.substr(0, sp1), target = line.substr(sp1 + 1, sp2 - sp1 - 1),
                    version = line.substr(sp2 + 1);
  if (method.empty() || method.size() > 16) {
    *error = Error(400, "malformed method");
    return false;
  }
  for (char c : method)
    if (!IsTokenChar(c)) {
      *error = Error(400, "malformed method");
      return false;
    }
  if (version != "HTTP/1.1" && version != "HTTP/1.0") {
    *error = Error(400, "unsupported HTTP version");
    return false;
  }
  if (target.empty() || target[0] != '/' || target.size() > 2048) {
    *error = Error(400, "malformed request target");
    return false;
  }
  for (char c : target)
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f) {
      *error = Error(400, "malformed request target");
      return false;
    }
  if (method != "GET" && method != "HEAD") {
    *error = Error(405, "only GET and HEAD");
    return false;
  }
  req->method = method;
  const size_t q = target.find('?');
  req->path = target.substr(0, q);
  req->query = q == std::string::npos ? "" : target.substr(q + 1);
  return true;
}

char Lower(char c) { return c >= 'A' && c <= 'Z' ? char(c - 'A' + 'a') : c; }

bool EqualsNoCase(const std::string& a, const std::string& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (Lower(a[i]) != Lower(b[i])) return false;
  return true;
}

std::string Trim(const std::string& s) {
  size_t a = 0, b = s.size();
  while (a < b && (s[a] == ' ' || s[a] == '\t')) ++a;
  while (b > a && (s[b - 1] == ' ' || s[b - 1] == '\t' || s[b - 1] == '\r')) --b;
  return s.substr(a, b - a);
}

/// The values of every header `name` (case-insensitive) in a request head.
std::vector<std::string> HeaderValues(const std::string& head, const std::string& name) {
  std::vector<std::string> out;
  size_t pos = head.find('\n');
  while (pos != std::string::npos && pos + 1 < head.size()) {
    const size_t start = pos + 1;
    const size_t end = head.find('\n', start);
    const std::string line = head.substr(start, end == std::string::npos ? std::string::npos : end - start);
    const size_t colon = line.find(':');
    if (colon != std::string::npos && EqualsNoCase(line.substr(0, colon), name))
      out.push_back(Trim(line.substr(colon + 1)));
    pos = end;
  }
  return out;
}

/// Percent-decoding ('+' stays '+': tokens are compared as the dashboard's script sends them).
std::string PercentDecode(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size() && std::isxdigit(static_cast<unsigned char>(s[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(s[i + 2]))) {
      out += char(std::stoi(s.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += s[i];
    }
  }
  return out;
}

/// The credentials a request presents: the bearer token of its Authorization header, or for the
/// dashboard page its `token` query parameter. `present` says whether it tried at all.
std::string PresentedToken(const std::string& head, const HttpRequest& req, bool* present, bool* ambiguous) {
  *present = false;
  *ambiguous = false;
  const auto auth = HeaderValues(head, "authorization");
  if (auth.size() > 1) {
    *present = true;
    *ambiguous = true;
    return "";
  }
  if (auth.size() == 1) {
    *present = true;
    const std::string& v = auth[0];
    const size_t sp = v.find_first_of(" \t");
    if (sp == std::string::npos || !EqualsNoCase(v.substr(0, sp), "bearer")) return "";
    return Trim(v.substr(sp + 1));
  }
  if (req.path == "/" || req.path == "/index.html") {
    std::istringstream q(req.query);
    for (std::string kv; std::getline(q, kv, '&');)
      if (kv.rfind("token=", 0) == 0) {
        *present = true;
        return PercentDecode(kv.substr(6));
      }
  }
  return "";
}
}  // namespace

bool ConstantTimeEquals(const std::string& given, const std::string& expected) {
  // Every byte of `given` is compared (against `expected` repeated), whatever the lengths; the
  // time depends on given.size() only.
  if (expected.empty()) return given.empty();
  volatile unsigned char diff = given.size() == expected.size() ? 0 : 1;
  for (size_t i = 0; i < given.size(); ++i)
    diff = diff | static_cast<unsigned char>(given[i] ^ expected[i % expected.size()]);
  return diff == 0 && given.size() == expected.size();
}

bool IsLoopbackAddress(const std::string& ipv4) {
  in_addr a{};
  return ::inet_pton(AF_INET, ipv4.c_str(), &a) == 1 && (ntohl(a.s_addr) >> 24) == 127;
}

Result<std::string> ReadHttpTokenFile(const std::string& path) {
  const std::string what = "--http-token-file " + path;
  // Checked on the open file (no race between the check and the read); symlinks are followed
  // (a Kubernetes Secret's files are symlinks).
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return Status(ErrorCode::kInvalidArgument, what + ": " + std::strerror(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) return Status(ErrorCode::kInvalidArgument, what + ": " + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) return Status(ErrorCode::kInvalidArgument, what + ": not a regular file");
  char mode[8];
  std::snprintf(mode, sizeof mode, "%04o", unsigned(st.st_mode & 07777));
  const bool root_owned = st.st_uid == 0;
  const char* open_to = (st.st_mode & 007) != 0                    ? "open to others"
                        : (st.st_mode & 020) != 0                  ? "writable by its group"
                        : (!root_owned && (st.st_mode & 070) != 0) ? "readable by its group"
                                                                   : nullptr;
  if (open_to)
    return Status(ErrorCode::kInvalidArgument,
                  what + ": permissions " + mode + " are too open (a secret " + open_to + "); chmod 600 " +
                      path + " (or 0440 owned by root, as a Kubernetes Secret with fsGroup)");
  if (st.st_size > 4098)
    return Status(ErrorCode::kInvalidArgument, what + ": over 4096 bytes (a token, not a file)");
  std::string token;
  char buf[4100];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return Status(ErrorCode::kInvalidArgument, what + ": cannot read it: " + std::strerror(errno));
    if (n == 0) break;
    token.append(buf, size_t(n));
    if (token.size() > 4098)
      return Status(ErrorCode::kInvalidArgument, what + ": over 4096 bytes (a token, not a file)");
  }
  if (!token.empty() && token.back() == '\n') token.pop_back();
  if (!token.empty() && token.back() == '\r') token.pop_back();
  if (token.empty())
    return Status(
        ErrorCode::kInvalidArgument,
        what + ": empty (put a random token in it: `(umask 077; openssl rand -hex 32 > " + path + ")`)");
  for (size_t i = 0; i < token.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(token[i]);
    if (c <= 0x20 || c >= 0x7f)
      return Status(ErrorCode::kInvalidArgument,
                    what + ": byte " + std::to_string(i) +
                        " is a space, control or non-ASCII character (one line of visible ASCII, e.g. "
                        "`openssl rand -hex 32`)");
  }
  if (token.size() > 4096) return Status(ErrorCode::kInvalidArgument, what + ": token over 4096 bytes");
  return token;
}

void HttpServer::Log(const std::string& line) {
  if (!opt_.log) return;
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

Status ParseHttpAddress(const std::string& text, HttpServerOptions* opt) {
  const size_t colon = text.rfind(':');
  if (colon == std::string::npos)
    return Status(ErrorCode::kInvalidArgument,
                  "--http " + text + ": expected HOST:PORT, e.g. 127.0.0.1:8080");
  std::string host = text.substr(0, colon);
  const std::string port = text.substr(colon + 1);
  if (host == "localhost") host = "127.0.0.1";
  in_addr a{};
  if (::inet_pton(AF_INET, host.c_str(), &a) != 1)
    return Status(ErrorCode::kInvalidArgument,
                  "--http " + text + ": host must be an IPv4 address or localhost");
  char* end = nullptr;
  errno = 0;
  const long p = port.empty() ? -1 : std::strtol(port.c_str(), &end, 10);
  if (port.empty() || errno != 0 || *end != '\0' || p < 0 || p > 65535)
    return Status(ErrorCode::kInvalidArgument, "--http " + text + ": port must be 0..65535");
  opt->address = host;
  opt->port = uint16_t(p);
  return Status::Ok();
}

Result<std::unique_ptr<HttpServer>> HttpServer::Start(const HttpServerOptions& opt, Handler handler) {
  std::unique_ptr<HttpServer> s(new HttpServer());
  s->opt_ = opt;
  s->handler_ = std::move(handler);
  const std::string where = opt.address + ":" + std::to_string(opt.port);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(opt.port);
  if (::inet_pton(AF_INET, opt.address.c_str(), &addr.sin_addr) != 1)
    return Status(ErrorCode::kInvalidArgument, "HTTP address " + where + ": not an IPv4 address");
  s->listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (s->listen_fd_ < 0) return Status(ErrorCode::kIo, "HTTP socket: " + std::string(std::strerror(errno)));
  const int one = 1;
  ::setsockopt(s->listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (::bind(s->listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0)
    return Status(ErrorCode::kIo, "HTTP bind " + where + ": " + std::strerror(errno));
  if (::listen(s->listen_fd_, 64) != 0 || !SetNonBlocking(s->listen_fd_))
    return Status(ErrorCode::kIo, "HTTP listen " + where + ": " + std::strerror(errno));
  socklen_t len = sizeof addr;
  ::getsockname(s->listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
  s->port_ = ntohs(addr.sin_port);
  if (::pipe2(s->wake_, O_CLOEXEC | O_NONBLOCK) != 0)
    return Status(ErrorCode::kIo, "HTTP pipe: " + std::string(std::strerror(errno)));
  HttpServer* raw = s.get();
  s->thread_ = std::thread([raw] { raw->Loop(); });
  return s;
}

HttpServer::~HttpServer() {
  stop_ = true;
  if (wake_[1] >= 0) {
    const char c = 1;
    (void)!::write(wake_[1], &c, 1);
  }
  if (thread_.joinable()) thread_.join();
  for (int fd : {listen_fd_, wake_[0], wake_[1]})
    if (fd >= 0) ::close(fd);
}

std::string HttpServer::url() const {
  const std::string host = opt_.address == "0.0.0.0" ? "127.0.0.1" : opt_.address;
  return "http://" + host + ":" + std::to_string(port_);
}

void HttpServer::Loop() {
  std::vector<Conn> conns;
  std::vector<pollfd> fds;
  while (!stop_) {
    fds.clear();
    fds.push_back({wake_[0], POLLIN, 0});
    fds.push_back({listen_fd_, POLLIN, 0});
    for (const Conn& c : conns) fds.push_back({c.fd, short(c.responding ? POLLOUT : POLLIN), 0});
    // Wake at the nearest deadline (at most every 200 ms) to time out slow clients.
    int wait_ms = 200;
    const auto now = Clock::now();
    for (const Conn& c : conns)
      wait_ms = std::min<int>(
          wait_ms, int(std::max<int64_t>(
                       0, std::chrono::duration_cast<std::chrono::milliseconds>(c.deadline - now).count())));
    if (::poll(fds.data(), fds.size(), wait_ms) < 0 && errno != EINTR) break;
    if (stop_) break;
    if (fds[0].revents & POLLIN) {
      char buf[64];
      while (::read(wake_[0], buf, sizeof buf) > 0) {
      }
    }
    // Existing connections first (their pollfd entries follow the first two).
    std::vector<Conn> keep;
    for (size_t i = 0; i < conns.size(); ++i) {
      Conn& c = conns[i];
      const short ev = fds[i + 2].revents;
      bool close_it = false;
      auto respond = [&](const HttpResponse& r, bool head_only) {
        c.out = Serialize(r, head_only);
        c.sent = 0;
        c.responding = true;
        c.in.clear();
        c.in.shrink_to_fit();
      };
      if (!c.responding && (ev & (POLLIN | POLLHUP | POLLERR))) {
        char buf[4096];
        const ssize_t n = ::recv(c.fd, buf, sizeof buf, 0);
        if (n <= 0) {
          if (n == 0 || (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) close_it = true;
        } else {
          c.in.append(buf, size_t(n));
          size_t end = c.in.find("\r\n\r\n");
          if (end == std::string::npos) end = c.in.find("\n\n");
          if (end == std::string::npos && c.in.size() > opt_.max_head_bytes) {
            ++bad_;
            respond(Error(431, "request head over " + std::to_string(opt_.max_head_bytes) + " bytes"), false);
          } else if (end != std::string::npos) {
            HttpRequest req;
            HttpResponse err;
            if (end > opt_.max_head_bytes) {
              ++bad_;
              respond(Error(431, "request head over " + std::to_string(opt_.max_head_bytes) + " bytes"),
                      false);
            } else if (!ParseHead(c.in.substr(0, end), &req, &err)) {
              ++bad_;
              respond(err, false);
            } else {
              req.peer = c.peer;
              req.server = this;
              bool present = false, ambiguous = false;
              const bool authorized =
                  opt_.bearer_token.empty() ||
                  (ConstantTimeEquals(PresentedToken(c.in.substr(0, end), req, &present, &ambiguous),
                                      opt_.bearer_token) &&
                   !ambiguous);
              if (!authorized) {
                // Nothing about the server or the path: the status, the scheme, one line.
                ++unauthorized_;
                Log("http: 401 for " + req.method + " " + req.path.substr(0, 100) + " from " + c.peer + ": " +
                    (ambiguous ? "several Authorization headers"
                     : present ? "wrong token"
                               : "no token"));
                c.out = Serialize(
                    {401, "text/plain; charset=utf-8", "401 Unauthorized: a bearer token is required\n"},
                    req.method == "HEAD",
                    std::string("WWW-Authenticate: Bearer realm=\"poseforest\"") +
                        (present ? ", error=\"invalid_token\"" : "") + "\r\n");
                c.sent = 0;
                c.responding = true;
                c.in.clear();
                c.in.shrink_to_fit();
              } else {
                HttpResponse r;
                try {
                  r = handler_(req);
                } catch (...) {
                  r = Error(500, "handler failed");
                }
                ++requests_;
                respond(r, req.method == "HEAD");
              }
            }
          }
        }
      } else if (c.responding && (ev & (POLLOUT | POLLHUP | POLLERR))) {
        const ssize_t n = ::send(c.fd, c.out.data() + c.sent, c.out.size() - c.sent, MSG_NOSIGNAL);
        if (n > 0) c.sent += size_t(n);
        if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) close_it = true;
        if (c.sent == c.out.size()) {
          ::shutdown(c.fd, SHUT_WR);
          close_it = true;
        }
      }
      if (!close_it && Clock::now() > c.deadline) {
        if (!c.responding) {
          // Slow client: one best-effort 408 (non-blocking), then close.
          ++bad_;
          const std::string r = Serialize(Error(408, "request not complete in time"), false);
          (void)::send(c.fd, r.data(), r.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
        }
        close_it = true;
      }
      if (close_it)
        ::close(c.fd);
      else
        keep.push_back(std::move(c));
    }
    conns.swap(keep);
    if (fds[1].revents & POLLIN) {
      for (;;) {
        sockaddr_in peer{};
        socklen_t peer_len = sizeof peer;
        const int fd = ::accept4(listen_fd_, reinterpret_cast<sockaddr*>(&peer), &peer_len,
                                 SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd < 0) break;
        char ip[INET_ADDRSTRLEN] = "?";
        ::inet_ntop(AF_INET, &peer.sin_addr, ip, sizeof ip);
        const std::string peer_text = std::string(ip) + ":" + std::to_string(ntohs(peer.sin_port));
        int from_peer = 0;
        for (const Conn& o : conns) from_peer += o.peer_ip == peer.sin_addr.s_addr;
        const bool over_total = int(conns.size()) >= opt_.max_connections;
        const bool over_peer = from_peer >= opt_.max_connections_per_peer;
        if (over_total || over_peer) {
          ++dropped_;
          if (over_peer)
            Log("http: 503 for a connection from " + peer_text + ": " + std::to_string(from_peer) +
                " already open from that address");
          const std::string r = Serialize(Error(503, "too many connections"), false);
          (void)::send(fd, r.data(), r.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
          // Read what already arrived so that close() sends FIN, not RST (which would discard
          // the 503 at the client).
          char sink[4096];
          while (::recv(fd, sink, sizeof sink, MSG_DONTWAIT) > 0) {
          }
          ::shutdown(fd, SHUT_WR);
          ::close(fd);
          continue;
        }
        Conn c;
        c.fd = fd;
        c.peer_ip = peer.sin_addr.s_addr;
        c.peer = peer_text;
        c.deadline = Clock::now() + opt_.timeout;
        conns.push_back(std::move(c));
      }
    }
  }
  for (Conn& c : conns) ::close(c.fd);
}

Result<std::string> HttpGet(const std::string& url, std::chrono::milliseconds timeout,
                            const std::string& bearer_token) {
  const std::string prefix = "http://";
  if (url.rfind(prefix, 0) != 0) return Status(ErrorCode::kInvalidArgument, url + ": only http:// URLs");
  const std::string rest = url.substr(prefix.size());
  const size_t slash = rest.find('/');
  const std::string hostport = rest.substr(0, slash);
  const std::string path = slash == std::string::npos ? "/" : rest.substr(slash);
  HttpServerOptions where;
  if (Status st = ParseHttpAddress(hostport, &where); !st.ok())
    return Status(ErrorCode::kInvalidArgument, url + ": expected http://HOST:PORT/PATH");
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(where.port);
  ::inet_pton(AF_INET, where.address.c_str(), &addr.sin_addr);
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (fd < 0) return Status(ErrorCode::kIo, url + ": socket: " + std::strerror(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  const auto deadline = Clock::now() + timeout;
  auto left_ms = [&] {
    return int(std::max<int64_t>(
        0, std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count()));
  };
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    if (errno != EINPROGRESS) return Status(ErrorCode::kIo, url + ": " + std::strerror(errno));
    pollfd p{fd, POLLOUT, 0};
    if (::poll(&p, 1, left_ms()) <= 0) return Status(ErrorCode::kIo, url + ": connect timed out");
    int err = 0;
    socklen_t len = sizeof err;
    ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
    if (err != 0) return Status(ErrorCode::kIo, url + ": " + std::strerror(err));
  }
  const std::string req = "GET " + path + " HTTP/1.1\r\nHost: " + hostport + "\r\n" +
                          (bearer_token.empty() ? "" : "Authorization: Bearer " + bearer_token + "\r\n") +
                          "Connection: close\r\n\r\n";
  size_t sent = 0;
  while (sent < req.size()) {
    pollfd p{fd, POLLOUT, 0};
    if (::poll(&p, 1, left_ms()) <= 0) return Status(ErrorCode::kIo, url + ": send timed out");
    const ssize_t n = ::send(fd, req.data() + sent, req.size() - sent, MSG_NOSIGNAL);
    if (n < 0 && errno != EAGAIN && errno != EINTR)
      return Status(ErrorCode::kIo, url + ": " + std::strerror(errno));
    if (n > 0) sent += size_t(n);
  }
  std::string resp;
  for (;;) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, left_ms()) <= 0) return Status(ErrorCode::kIo, url + ": no complete reply in time");
    char buf[16384];
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n == 0) break;
    if (n < 0) {
      if (errno == EAGAIN || errno == EINTR) continue;
      return Status(ErrorCode::kIo, url + ": " + std::strerror(errno));
    }
    resp.append(buf, size_t(n));
    if (resp.size() > (64u << 20)) return Status(ErrorCode::kDataLoss, url + ": reply over 64 MiB");
  }
  const size_t head_end = resp.find("\r\n\r\n");
  if (resp.rfind("HTTP/1.", 0) != 0 || head_end == std::string::npos || resp.size() < 12)
    return Status(ErrorCode::kDataLoss, url + ": not an HTTP reply");
  const int code = std::atoi(resp.substr(9, 3).c_str());
  std::string body = resp.substr(head_end + 4);
  if (code == 401)
    return Status(
        ErrorCode::kInvalidArgument,
        url + ": HTTP 401: " + body.substr(0, body.find('\n')) +
            (bearer_token.empty() ? " (the coordinator has --http-token-file: pass the same token file)"
                                  : " (the token sent is not the coordinator's)"));
  if (code != 200)
    return Status(code == 404 ? ErrorCode::kNotFound : ErrorCode::kIo,
                  url + ": HTTP " + std::to_string(code) + ": " + body.substr(0, body.find('\n')));
  return body;
}

}  // namespace poseforest::dist
