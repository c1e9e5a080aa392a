#include "coordinator/monitoring/http_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <openssl/crypto.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
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

struct SslCtxFree {
  void operator()(SSL_CTX* c) const { SSL_CTX_free(c); }
};
struct SslFree {
  void operator()(SSL* s) const { SSL_free(s); }
};
struct BioFree {
  void operator()(BIO* b) const { BIO_free(b); }
};
struct X509Free {
  void operator()(X509* x) const { X509_free(x); }
};
struct PkeyFree {
  void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); }
};
using SslCtxPtr = std::unique_ptr<SSL_CTX, SslCtxFree>;
using SslPtr = std::unique_ptr<SSL, SslFree>;
using BioPtr = std::unique_ptr<BIO, BioFree>;
using X509Ptr = std::unique_ptr<X509, X509Free>;
using PkeyPtr = std::unique_ptr<EVP_PKEY, PkeyFree>;

/// The reasons of OpenSSL's queued errors of this thread ("no start line; ..."); empties the queue.
std::string OpenSslReasons() {
  std::string out;
  for (unsigned long e; (e = ERR_get_error()) != 0;) {
    char buf[256];
    const char* r = ERR_reason_error_string(e);
    if (!r) {
      ERR_error_string_n(e, buf, sizeof buf);
      r = buf;
    }
    if (out.find(r) != std::string::npos) continue;
    if (!out.empty()) out += "; ";
    out += r;
  }
  return out.empty() ? "no details" : out;
}

std::string Asn1TimeText(const ASN1_TIME* t) {
  BioPtr b(BIO_new(BIO_s_mem()));
  if (!b || ASN1_TIME_print(b.get(), t) != 1) return "?";
  char* data = nullptr;
  const long n = BIO_get_mem_data(b.get(), &data);
  return n > 0 ? std::string(data, size_t(n)) : "?";
}

/// Keeps this thread from being killed by SIGPIPE while OpenSSL write()s to a socket the peer
/// closed (its socket BIO does not use MSG_NOSIGNAL): blocked while it lives, and a SIGPIPE raised
/// meanwhile is taken off this thread's pending set before the old mask comes back.
class SigpipeBlock {
 public:
  SigpipeBlock() {
    sigemptyset(&pipe_);
    sigaddset(&pipe_, SIGPIPE);
    sigset_t pending;
    sigemptyset(&pending);
    had_pending_ = ::sigpending(&pending) == 0 && sigismember(&pending, SIGPIPE) == 1;
    ::pthread_sigmask(SIG_BLOCK, &pipe_, &old_);
  }
  ~SigpipeBlock() {
    sigset_t pending;
    sigemptyset(&pending);
    if (!had_pending_ && ::sigpending(&pending) == 0 && sigismember(&pending, SIGPIPE) == 1) {
      const timespec zero{0, 0};
      (void)::sigtimedwait(&pipe_, nullptr, &zero);
    }
    ::pthread_sigmask(SIG_SETMASK, &old_, nullptr);
  }
  SigpipeBlock(const SigpipeBlock&) = delete;
  SigpipeBlock& operator=(const SigpipeBlock&) = delete;

 private:
  sigset_t pipe_{}, old_{};
  bool had_pending_ = false;
};

/// The bytes of `path`, read through one open file (no race between the checks and the read;
/// symlinks are followed: a Kubernetes Secret's files are symlinks): a regular file of at most
/// `max_bytes` (else the error `too_big`); with `secret`, no access for others nor, unless root
/// owns it, for its group (ssh's rule for a private key). Errors start with `what`.
Result<std::string> ReadCheckedFile(const std::string& path, const std::string& what, bool secret,
                                    size_t max_bytes, const std::string& too_big) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return Status(ErrorCode::kInvalidArgument, what + ": " + std::strerror(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) return Status(ErrorCode::kInvalidArgument, what + ": " + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) return Status(ErrorCode::kInvalidArgument, what + ": not a regular file");
  if (secret) {
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
  }
  if (st.st_size > off_t(max_bytes)) return Status(ErrorCode::kInvalidArgument, too_big);
  std::string text;
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return Status(ErrorCode::kInvalidArgument, what + ": cannot read it: " + std::strerror(errno));
    if (n == 0) break;
    text.append(buf, size_t(n));
    if (text.size() > max_bytes) return Status(ErrorCode::kInvalidArgument, too_big);
  }
  OPENSSL_cleanse(buf, sizeof buf);
  return text;
}

/// A private key's PEM text is wiped from memory when this goes.
struct WipedString {
  std::string text;
  ~WipedString() {
    if (!text.empty()) OPENSSL_cleanse(text.data(), text.size());
  }
};

int NoPassphrase(char*, int, int, void*) { return -1; }  // never prompt on a terminal

/// OpenSSL's server context for `cert_file` (PEM chain) and `key_file` (PEM key): TLS 1.2+.
Result<SslCtxPtr> MakeServerContext(const std::string& cert_file, const std::string& key_file) {
  if (cert_file.empty() != key_file.empty())
    return Status(
        ErrorCode::kInvalidArgument,
        std::string("--http-tls-cert and --http-tls-key go together (give both or neither); only ") +
            (cert_file.empty() ? "--http-tls-key" : "--http-tls-cert") + " was given");
  const std::string cert_what = "--http-tls-cert " + cert_file, key_what = "--http-tls-key " + key_file;
  auto cert_pem = ReadCheckedFile(cert_file, cert_what, false, size_t(1) << 20,
                                  cert_what + ": over 1 MiB (a PEM certificate chain is a few KiB)");
  if (!cert_pem.ok()) return cert_pem.status();
  WipedString key_pem;
  {
    auto k = ReadCheckedFile(key_file, key_what, true, size_t(64) << 10,
                             key_what + ": over 64 KiB (a PEM private key is a few KiB)");
    if (!k.ok()) return k.status();
    key_pem.text = std::move(*k);
  }
  ERR_clear_error();
  SslCtxPtr ctx(SSL_CTX_new(TLS_server_method()));
  if (!ctx) return Status(ErrorCode::kInternal, "TLS: cannot create a context: " + OpenSslReasons());
  SSL_CTX_set_min_proto_version(ctx.get(), TLS1_2_VERSION);
  SSL_CTX_set_options(ctx.get(), SSL_OP_NO_RENEGOTIATION | SSL_OP_CIPHER_SERVER_PREFERENCE);
  SSL_CTX_set_mode(ctx.get(), SSL_MODE_ENABLE_PARTIAL_WRITE | SSL_MODE_ACCEPT_MOVING_WRITE_BUFFER);

  // The certificate, then the rest of the chain.
  BioPtr bio(BIO_new_mem_buf(cert_pem->data(), int(cert_pem->size())));
  X509Ptr leaf(PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr));
  if (!leaf)
    return Status(ErrorCode::kInvalidArgument,
                  cert_what +
                      ": no PEM certificate in it (expected \"-----BEGIN CERTIFICATE-----\"; OpenSSL: " +
                      OpenSslReasons() + ")");
  if (X509_cmp_current_time(X509_get0_notAfter(leaf.get())) < 0)
    return Status(ErrorCode::kInvalidArgument, cert_what + ": expired on " +
                                                   Asn1TimeText(X509_get0_notAfter(leaf.get())) +
                                                   " (every client would refuse it; renew it)");
  if (X509_cmp_current_time(X509_get0_notBefore(leaf.get())) > 0)
    return Status(ErrorCode::kInvalidArgument, cert_what + ": not valid before " +
                                                   Asn1TimeText(X509_get0_notBefore(leaf.get())) +
                                                   " (check this machine's clock)");
  if (SSL_CTX_use_certificate(ctx.get(), leaf.get()) != 1)
    return Status(ErrorCode::kInvalidArgument, cert_what + ": refused by OpenSSL: " + OpenSslReasons());
  for (int n = 2;; ++n) {
    X509* extra = PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr);
    if (!extra) {
      // The end of the text reads as "no start line"; anything else is a malformed certificate.
      const unsigned long e = ERR_peek_last_error();
      if (e != 0 && !(ERR_GET_LIB(e) == ERR_LIB_PEM && ERR_GET_REASON(e) == PEM_R_NO_START_LINE))
        return Status(ErrorCode::kInvalidArgument, cert_what + ": certificate " + std::to_string(n) +
                                                       " of the chain is malformed: " + OpenSslReasons());
      ERR_clear_error();
      break;
    }
    if (SSL_CTX_add0_chain_cert(ctx.get(), extra) != 1) {
      X509_free(extra);
      return Status(ErrorCode::kInvalidArgument, cert_what + ": certificate " + std::to_string(n) +
                                                     " of the chain refused: " + OpenSslReasons());
    }
  }

  // The key: unencrypted, and the certificate's.
  if (key_pem.text.find("ENCRYPTED") != std::string::npos)
    return Status(ErrorCode::kInvalidArgument,
                  key_what +
                      ": encrypted with a passphrase, which the coordinator cannot ask for; give it "
                      "unencrypted (openssl pkey -in " +
                      key_file + " -out PLAIN.key; chmod 600 PLAIN.key)");
  BioPtr key_bio(BIO_new_mem_buf(key_pem.text.data(), int(key_pem.text.size())));
  PkeyPtr key(PEM_read_bio_PrivateKey(key_bio.get(), nullptr, NoPassphrase, nullptr));
  if (!key)
    return Status(ErrorCode::kInvalidArgument,
                  key_what +
                      ": no PEM private key in it (expected \"-----BEGIN PRIVATE KEY-----\"; OpenSSL: " +
                      OpenSslReasons() + ")");
  if (X509_check_private_key(leaf.get(), key.get()) != 1) {
    ERR_clear_error();
    return Status(ErrorCode::kInvalidArgument, key_what + ": does not match the certificate in " + cert_what +
                                                   " (the certificate was issued for another key)");
  }
  if (SSL_CTX_use_PrivateKey(ctx.get(), key.get()) != 1 || SSL_CTX_check_private_key(ctx.get()) != 1)
    return Status(ErrorCode::kInvalidArgument, key_what + ": refused by OpenSSL: " + OpenSslReasons());
  return ctx;
}

struct Conn {
  enum class Phase { kHandshake, kReading, kWriting, kClosing };
  int fd = -1;
  uint32_t peer_ip = 0;  ///< network order
  std::string peer;      ///< "IP:PORT"
  std::string in, out;
  size_t sent = 0;
  Phase phase = Phase::kReading;
  short want = POLLIN;  ///< what the next step waits for (TLS may want to write while reading)
  SslPtr ssl;           ///< with TLS
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
  auto read = ReadCheckedFile(path, what, true, 4098, what + ": over 4096 bytes (a token, not a file)");
  if (!read.ok()) return read.status();
  std::string token = std::move(*read);
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

struct HttpServer::Tls {
  SslCtxPtr ctx;
};

Status CheckHttpTlsFiles(const std::string& cert_file, const std::string& key_file) {
  auto ctx = MakeServerContext(cert_file, key_file);
  return ctx.ok() ? Status::Ok() : ctx.status();
}

Status CheckHttpCaFile(const std::string& ca_file) {
  const std::string what = "--http-ca-file " + ca_file;
  auto pem = ReadCheckedFile(ca_file, what, false, size_t(16) << 20,
                             what + ": over 16 MiB (a PEM file of CA certificates)");
  if (!pem.ok()) return pem.status();
  ERR_clear_error();
  BioPtr bio(BIO_new_mem_buf(pem->data(), int(pem->size())));
  X509Ptr first(PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr));
  if (!first)
    return Status(ErrorCode::kInvalidArgument,
                  what + ": no PEM certificate in it (expected \"-----BEGIN CERTIFICATE-----\"; OpenSSL: " +
                      OpenSslReasons() + ")");
  ERR_clear_error();
  return Status::Ok();
}

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
  return (tls_ ? "https://" : "http://") + host + ":" + std::to_string(port_);
}

void HttpServer::Loop() {
  // OpenSSL writes with write(), which raises SIGPIPE on a socket the peer closed: never on this
  // thread (the error comes back as EPIPE instead; a SIGPIPE left pending here is harmless).
  {
    sigset_t pipe_set;
    sigemptyset(&pipe_set);
    sigaddset(&pipe_set, SIGPIPE);
    ::pthread_sigmask(SIG_BLOCK, &pipe_set, nullptr);
  }
  std::vector<Conn> conns;
  std::vector<pollfd> fds;
  while (!stop_) {
    fds.clear();
    fds.push_back({wake_[0], POLLIN, 0});
    fds.push_back({listen_fd_, POLLIN, 0});
    for (const Conn& c : conns) fds.push_back({c.fd, c.want, 0});
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
      auto respond_raw = [&](std::string bytes) {
        c.out = std::move(bytes);
        c.sent = 0;
        c.phase = Conn::Phase::kWriting;
        c.want = POLLOUT;
        c.in.clear();
        c.in.shrink_to_fit();
      };
      auto respond = [&](const HttpResponse& r, bool head_only) { respond_raw(Serialize(r, head_only)); };
      // One complete request head in c.in: answer it. False while the head is incomplete.
      auto answer_head = [&]() -> bool {
        // A TLS ClientHello (a handshake record, version 3.x) to a plain port: refused at once rather
        // than at the timeout, so that an https:// client hears at once that this is not TLS.
        if (!c.ssl && c.in.size() >= 2 && c.in[0] == '\x16' && c.in[1] == '\x03') {
          ++bad_;
          respond(Error(400, "this port speaks plain HTTP, not TLS: use http://"), false);
          return true;
        }
        size_t end = c.in.find("\r\n\r\n");
        if (end == std::string::npos) end = c.in.find("\n\n");
        if (end == std::string::npos && c.in.size() > opt_.max_head_bytes) {
          ++bad_;
          respond(Error(431, "request head over " + std::to_string(opt_.max_head_bytes) + " bytes"), false);
          return true;
        }
        if (end == std::string::npos) return false;
        HttpRequest req;
        HttpResponse err;
        if (end > opt_.max_head_bytes) {
          ++bad_;
          respond(Error(431, "request head over " + std::to_string(opt_.max_head_bytes) + " bytes"), false);
          return true;
        }
        if (!ParseHead(c.in.substr(0, end), &req, &err)) {
          ++bad_;
          respond(err, false);
          return true;
        }
        req.peer = c.peer;
        req.server = this;
        bool present = false, ambiguous = false;
        // /healthz is open (probes carry no secret; its "ok" reveals nothing).
        const bool authorized =
            opt_.bearer_token.empty() || req.path == "/healthz" ||
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
          respond_raw(
              Serialize({401, "text/plain; charset=utf-8", "401 Unauthorized: a bearer token is required\n"},
                        req.method == "HEAD",
                        std::string("WWW-Authenticate: Bearer realm=\"poseforest\"") +
                            (present ? ", error=\"invalid_token\"" : "") + "\r\n"));
          return true;
        }
        HttpResponse r;
        try {
          r = handler_(req);
        } catch (...) {
          r = Error(500, "handler failed");
        }
        ++requests_;
        respond(r, req.method == "HEAD");
        return true;
      };
      // A failed TLS handshake: counted and logged unless the peer sent nothing at all (a port
      // check); plain HTTP sent to the port gets a plain 400 that says to use https://.
      auto handshake_failed = [&](int ssl_error) {
        const unsigned long first = ERR_peek_error();
        const bool plain_http =
            ERR_GET_LIB(first) == ERR_LIB_SSL && ERR_GET_REASON(first) == SSL_R_HTTP_REQUEST;
        const std::string why =
            ssl_error == SSL_ERROR_SYSCALL && first == 0 ? "connection closed" : OpenSslReasons();
        ERR_clear_error();
        if (BIO_number_read(SSL_get_rbio(c.ssl.get())) == 0) return;
        ++tls_failed_;
        Log("http: TLS handshake with " + c.peer +
            " failed: " + (plain_http ? std::string("plain HTTP sent to the HTTPS port") : why));
        if (plain_http) {
          const std::string r =
              Serialize(Error(400, "this port speaks HTTPS only: use https:// instead of http://"), false);
          (void)::send(c.fd, r.data(), r.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
          char sink[4096];
          while (::recv(c.fd, sink, sizeof sink, MSG_DONTWAIT) > 0) {
          }
          ::shutdown(c.fd, SHUT_WR);
        }
      };
      // The next step of an SSL_* call that returned `r` <= 0: wait (true) or give up (false).
      auto ssl_wait = [&](int r) {
        const int e = SSL_get_error(c.ssl.get(), r);
        if (e == SSL_ERROR_WANT_READ) {
          c.want = POLLIN;
          return true;
        }
        if (e == SSL_ERROR_WANT_WRITE) {
          c.want = POLLOUT;
          return true;
        }
        ERR_clear_error();
        return false;
      };
      if (ev != 0 && c.phase == Conn::Phase::kHandshake) {
        ERR_clear_error();
        const int r = SSL_accept(c.ssl.get());
        if (r == 1) {
          c.phase = Conn::Phase::kReading;  // the request may have come with the last flight: read now
          c.want = POLLIN;
        } else {
          const int e = SSL_get_error(c.ssl.get(), r);
          if (e == SSL_ERROR_WANT_READ) {
            c.want = POLLIN;
          } else if (e == SSL_ERROR_WANT_WRITE) {
            c.want = POLLOUT;
          } else {
            handshake_failed(e);
            close_it = true;
          }
        }
      } else if (ev != 0 && c.phase == Conn::Phase::kReading) {
        c.want = POLLIN;
      }
      if (!close_it && ev != 0 && c.phase == Conn::Phase::kReading) {
        // Until the socket (and OpenSSL's buffer) is drained or the head is complete.
        for (;;) {
          char buf[4096];
          ssize_t n = 0;
          if (c.ssl) {
            ERR_clear_error();
            const int r = SSL_read(c.ssl.get(), buf, int(sizeof buf));
            if (r <= 0) {
              if (!ssl_wait(r)) close_it = true;
              break;
            }
            n = r;
          } else {
            n = ::recv(c.fd, buf, sizeof buf, 0);
            if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR))
              close_it = true;
            if (n <= 0) break;
          }
          c.in.append(buf, size_t(n));
          if (answer_head()) break;
        }
      } else if (ev != 0 && c.phase == Conn::Phase::kWriting) {
        while (c.sent < c.out.size()) {
          if (c.ssl) {
            ERR_clear_error();
            const int r = SSL_write(c.ssl.get(), c.out.data() + c.sent,
                                    int(std::min<size_t>(c.out.size() - c.sent, 1 << 20)));
            if (r <= 0) {
              if (!ssl_wait(r)) close_it = true;
              break;
            }
            c.sent += size_t(r);
          } else {
            const ssize_t n = ::send(c.fd, c.out.data() + c.sent, c.out.size() - c.sent, MSG_NOSIGNAL);
            if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) close_it = true;
            if (n <= 0) break;
            c.sent += size_t(n);
          }
        }
        if (!close_it && c.sent == c.out.size()) {
          if (c.ssl) {
            c.phase = Conn::Phase::kClosing;
          } else {
            ::shutdown(c.fd, SHUT_WR);
            close_it = true;
          }
        }
      }
      if (!close_it && ev != 0 && c.phase == Conn::Phase::kClosing) {
        // TLS close_notify (so that the client knows the reply is complete), then close.
        ERR_clear_error();
        const int r = SSL_shutdown(c.ssl.get());
        if (r < 0 && SSL_get_error(c.ssl.get(), r) == SSL_ERROR_WANT_WRITE) {
          c.want = POLLOUT;
        } else {
          ERR_clear_error();
          ::shutdown(c.fd, SHUT_WR);
          close_it = true;
        }
      }
      if (!close_it && Clock::now() > c.deadline) {
        // Slow client (over TLS: the handshake included): one best-effort 408 once HTTP is
        // spoken (non-blocking), then close.
        if (c.phase == Conn::Phase::kHandshake || c.phase == Conn::Phase::kReading) ++bad_;
        if (c.phase == Conn::Phase::kReading) {
          const std::string r = Serialize(Error(408, "request not complete in time"), false);
          if (c.ssl) {
            ERR_clear_error();
            (void)SSL_write(c.ssl.get(), r.data(), int(r.size()));
            ERR_clear_error();
          } else {
            (void)::send(c.fd, r.data(), r.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
          }
        }
        close_it = true;
      }
      if (close_it) {
        c.ssl.reset();
        ::close(c.fd);
      } else {
        keep.push_back(std::move(c));
      }
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
          // Plain HTTP: a 503. TLS: just closed (before a handshake there is no way to say it).
          if (!tls_) {
            const std::string r = Serialize(Error(503, "too many connections"), false);
            (void)::send(fd, r.data(), r.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
          }
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
        if (tls_) {
          ERR_clear_error();
          c.ssl.reset(SSL_new(tls_->ctx.get()));
          if (!c.ssl || SSL_set_fd(c.ssl.get(), fd) != 1) {
            ERR_clear_error();
            ++dropped_;
            c.ssl.reset();
            ::close(fd);
            continue;
          }
          SSL_set_accept_state(c.ssl.get());
          c.phase = Conn::Phase::kHandshake;
          c.want = POLLIN;  // the ClientHello
        }
        conns.push_back(std::move(c));
      }
    }
  }
  for (Conn& c : conns) {
    c.ssl.reset();
    ::close(c.fd);
  }
}

namespace {
/// An http:// or https:// URL taken apart (HttpGet).
struct ParsedUrl {
  bool tls = false;
  std::string host;      ///< as written (a name or an IPv4 literal)
  std::string hostport;  ///< for the Host header
  uint16_t port = 0;
  std::string path;
};

Result<ParsedUrl> ParseUrl(const std::string& url) {
  ParsedUrl u;
  std::string rest;
  if (url.rfind("http://", 0) == 0) {
    rest = url.substr(7);
  } else if (url.rfind("https://", 0) == 0) {
    u.tls = true;
    rest = url.substr(8);
  } else {
    return Status(ErrorCode::kInvalidArgument, url + ": expected http://HOST[:PORT][/PATH] or https://...");
  }
  const size_t slash = rest.find('/');
  u.hostport = rest.substr(0, slash);
  u.path = slash == std::string::npos ? "/" : rest.substr(slash);
  const size_t colon = u.hostport.rfind(':');
  u.host = u.hostport.substr(0, colon);
  long port = u.tls ? 443 : 80;
  if (colon != std::string::npos) {
    const std::string p = u.hostport.substr(colon + 1);
    char* end = nullptr;
    errno = 0;
    port = p.empty() ? -1 : std::strtol(p.c_str(), &end, 10);
    if (p.empty() || errno != 0 || *end != '\0' || port < 1 || port > 65535)
      return Status(ErrorCode::kInvalidArgument, url + ": the port must be 1..65535");
  }
  u.port = uint16_t(port);
  bool host_ok = !u.host.empty() && u.host.size() <= 253;
  for (char c : u.host)
    host_ok = host_ok && (std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-');
  if (!host_ok)
    return Status(ErrorCode::kInvalidArgument,
                  url + ": expected http[s]://HOST[:PORT][/PATH] with HOST an IPv4 address or a host name");
  return u;
}
}  // namespace

Result<std::string> HttpGet(const std::string& url, std::chrono::milliseconds timeout,
                            const std::string& bearer_token, const std::string& ca_file) {
  auto parsed = ParseUrl(url);
  if (!parsed.ok()) return parsed.status();
  const ParsedUrl& u = *parsed;
  if (!ca_file.empty() && !u.tls)
    return Status(ErrorCode::kInvalidArgument, url + ": --http-ca-file is for https:// URLs");
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(u.port);
  const bool ip_literal = ::inet_pton(AF_INET, u.host.c_str(), &addr.sin_addr) == 1;
  if (!ip_literal) {
    if (u.host == "localhost") {
      addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    } else {
      addrinfo hints{};
      hints.ai_family = AF_INET;
      hints.ai_socktype = SOCK_STREAM;
      addrinfo* found = nullptr;
      const int rc = ::getaddrinfo(u.host.c_str(), nullptr, &hints, &found);
      if (rc != 0 || !found)
        return Status(ErrorCode::kIo, url + ": cannot resolve " + u.host + ": " + ::gai_strerror(rc));
      addr.sin_addr = reinterpret_cast<const sockaddr_in*>(found->ai_addr)->sin_addr;
      ::freeaddrinfo(found);
    }
  }
  // The TLS context before connecting: a bad CA file is an error at once.
  SslCtxPtr ctx;
  if (u.tls) {
    if (!ca_file.empty()) POSEFOREST_RETURN_IF_ERROR(CheckHttpCaFile(ca_file));
    ERR_clear_error();
    ctx.reset(SSL_CTX_new(TLS_client_method()));
    if (!ctx)
      return Status(ErrorCode::kInternal, url + ": TLS: cannot create a context: " + OpenSslReasons());
    SSL_CTX_set_min_proto_version(ctx.get(), TLS1_2_VERSION);
    // A peer that closes without close_notify reads as the end; the Content-Length check below
    // catches a truncated reply.
    SSL_CTX_set_options(ctx.get(), SSL_OP_IGNORE_UNEXPECTED_EOF | SSL_OP_NO_RENEGOTIATION);
    SSL_CTX_set_mode(ctx.get(), SSL_MODE_ENABLE_PARTIAL_WRITE | SSL_MODE_ACCEPT_MOVING_WRITE_BUFFER);
    SSL_CTX_set_verify(ctx.get(), SSL_VERIFY_PEER, nullptr);
    const int loaded = ca_file.empty() ? SSL_CTX_set_default_verify_paths(ctx.get())
                                       : SSL_CTX_load_verify_locations(ctx.get(), ca_file.c_str(), nullptr);
    if (loaded != 1)
      return Status(ErrorCode::kInvalidArgument,
                    (ca_file.empty() ? url + ": the system's trust store" : "--http-ca-file " + ca_file) +
                        ": cannot be loaded: " + OpenSslReasons());
  }
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (fd < 0) return Status(ErrorCode::kIo, url + ": socket: " + std::strerror(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  const auto deadline = Clock::now() + timeout;
  auto wait = [&](short events) {
    const int left = int(std::max<int64_t>(
        0, std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count()));
    pollfd p{fd, events, 0};
    return ::poll(&p, 1, left) > 0;
  };
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    if (errno != EINPROGRESS) return Status(ErrorCode::kIo, url + ": " + std::strerror(errno));
    if (!wait(POLLOUT)) return Status(ErrorCode::kIo, url + ": connect timed out");
    int err = 0;
    socklen_t len = sizeof err;
    ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
    if (err != 0) return Status(ErrorCode::kIo, url + ": " + std::strerror(err));
  }
  SigpipeBlock no_sigpipe;  // OpenSSL's write() to a closed socket
  SslPtr ssl;
  // Waits for what an SSL_* call that returned `r` <= 0 needs; false: it failed or timed out.
  auto ssl_wait = [&](int r, bool* timed_out) {
    const int e = SSL_get_error(ssl.get(), r);
    *timed_out = false;
    if (e != SSL_ERROR_WANT_READ && e != SSL_ERROR_WANT_WRITE) return false;
    if (!wait(e == SSL_ERROR_WANT_READ ? POLLIN : POLLOUT)) {
      *timed_out = true;
      return false;
    }
    return true;
  };
  if (u.tls) {
    ssl.reset(SSL_new(ctx.get()));
    if (!ssl || SSL_set_fd(ssl.get(), fd) != 1)
      return Status(ErrorCode::kInternal, url + ": TLS: " + OpenSslReasons());
    if (ip_literal) {
      X509_VERIFY_PARAM_set1_ip_asc(SSL_get0_param(ssl.get()), u.host.c_str());
    } else {
      SSL_set_tlsext_host_name(ssl.get(), u.host.c_str());
      SSL_set1_host(ssl.get(), u.host.c_str());
    }
    for (;;) {
      ERR_clear_error();
      const int r = SSL_connect(ssl.get());
      if (r == 1) break;
      const int e = SSL_get_error(ssl.get(), r);
      bool timed_out = false;
      if (ssl_wait(r, &timed_out)) continue;
      if (timed_out) return Status(ErrorCode::kIo, url + ": TLS handshake timed out");
      const long verify = SSL_get_verify_result(ssl.get());
      if (verify != X509_V_OK) {
        ERR_clear_error();
        const std::string why = X509_verify_cert_error_string(verify);
        if (verify == X509_V_ERR_HOSTNAME_MISMATCH || verify == X509_V_ERR_IP_ADDRESS_MISMATCH)
          return Status(ErrorCode::kInvalidArgument,
                        url + ": the server's certificate is not for " + u.host + " (" + why +
                            "); use the host name it was issued for, or issue one with " + u.host +
                            " in its subjectAltName");
        return Status(ErrorCode::kInvalidArgument,
                      url + ": the server's certificate is not trusted (" + why + "); " +
                          (ca_file.empty() ? "it was checked against the system's trust store: give the CA "
                                             "that signed it with --http-ca-file FILE"
                                           : "it does not chain to a CA in --http-ca-file " + ca_file));
      }
      const unsigned long first = ERR_peek_error();
      if (e == SSL_ERROR_SYSCALL && first == 0)
        return Status(ErrorCode::kIo, url + ": the connection was closed during the TLS handshake");
      const bool plain =
          ERR_GET_LIB(first) == ERR_LIB_SSL && (ERR_GET_REASON(first) == SSL_R_WRONG_VERSION_NUMBER ||
                                                ERR_GET_REASON(first) == SSL_R_PACKET_LENGTH_TOO_LONG);
      return Status(ErrorCode::kInvalidArgument,
                    url + ": TLS handshake failed (" + OpenSslReasons() + ")" +
                        (plain ? "; the server does not speak TLS: is it http://?" : ""));
    }
  }
  const std::string req = "GET " + u.path + " HTTP/1.1\r\nHost: " + u.hostport + "\r\n" +
                          (bearer_token.empty() ? "" : "Authorization: Bearer " + bearer_token + "\r\n") +
                          "Connection: close\r\n\r\n";
  size_t sent = 0;
  while (sent < req.size()) {
    if (ssl) {
      ERR_clear_error();
      const int r = SSL_write(ssl.get(), req.data() + sent, int(req.size() - sent));
      if (r > 0) {
        sent += size_t(r);
        continue;
      }
      bool timed_out = false;
      if (!ssl_wait(r, &timed_out))
        return Status(ErrorCode::kIo,
                      url + (timed_out ? ": send timed out" : ": TLS send: " + OpenSslReasons()));
      continue;
    }
    if (!wait(POLLOUT)) return Status(ErrorCode::kIo, url + ": send timed out");
    const ssize_t n = ::send(fd, req.data() + sent, req.size() - sent, MSG_NOSIGNAL);
    if (n < 0 && errno != EAGAIN && errno != EINTR)
      return Status(ErrorCode::kIo, url + ": " + std::strerror(errno));
    if (n > 0) sent += size_t(n);
  }
  std::string resp;
  for (;;) {
    char buf[16384];
    if (ssl) {
      ERR_clear_error();
      const int r = SSL_read(ssl.get(), buf, int(sizeof buf));
      if (r > 0) {
        resp.append(buf, size_t(r));
      } else if (SSL_get_error(ssl.get(), r) == SSL_ERROR_ZERO_RETURN) {
        break;
      } else {
        bool timed_out = false;
        if (!ssl_wait(r, &timed_out))
          return Status(ErrorCode::kIo, url + (timed_out ? ": no complete reply in time"
                                                         : ": TLS receive: " + OpenSslReasons()));
        continue;
      }
    } else {
      if (!wait(POLLIN)) return Status(ErrorCode::kIo, url + ": no complete reply in time");
      const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
      if (n == 0) break;
      if (n < 0) {
        if (errno == EAGAIN || errno == EINTR) continue;
        return Status(ErrorCode::kIo, url + ": " + std::strerror(errno));
      }
      resp.append(buf, size_t(n));
    }
    if (resp.size() > (64u << 20)) return Status(ErrorCode::kDataLoss, url + ": reply over 64 MiB");
  }
  const size_t head_end = resp.find("\r\n\r\n");
  if (resp.rfind("HTTP/1.", 0) != 0 || head_end == std::string::npos || resp.size() < 12)
    return Status(ErrorCode::kDataLoss, url + ": not an HTTP reply");
  const int code = std::atoi(resp.substr(9, 3).c_str());
  std::string body = resp.substr(head_end + 4);
  if (const auto length = HeaderValues(resp.substr(0, head_end), "content-length"); length.size() == 1) {
    char* end = nullptr;
    const unsigned long long n = std::strtoull(length[0].c_str(), &end, 10);
    if (end == length[0].c_str() || *end != '\0' || n != body.size())
      return Status(ErrorCode::kDataLoss, url + ": reply truncated or malformed (" +
                                              std::to_string(body.size()) +
                                              " bytes of body, Content-Length " + length[0] + ")");
  }
  if (code == 401)
    return Status(
        ErrorCode::kInvalidArgument,
        url + ": HTTP 401: " + body.substr(0, body.find('\n')) +
            (bearer_token.empty() ? " (the coordinator has --http-token-file: pass the same token file)"
                                  : " (the token sent is not the coordinator's)"));
  if (code != 200)
    return Status(code == 404 ? ErrorCode::kNotFound
                  : code == 400
                      ? ErrorCode::kInvalidArgument  // e.g. http:// to an HTTPS port: retrying will not help
                      : ErrorCode::kIo,
                  url + ": HTTP " + std::to_string(code) + ": " + body.substr(0, body.find('\n')));
  return body;
}

}  // namespace poseforest::dist
