#include "proto/http/http_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
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
#include <list>
#include <set>
#include <sstream>
#include <system_error>
#include <vector>

// cpp-httplib with its OpenSSL support (CPPHTTPLIB_OPENSSL_SUPPORT comes with the pkg-config target).
#include <httplib.h>

namespace poseforest::proto::http {

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
                      ": encrypted with a passphrase, which the server cannot ask for; give it "
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

std::vector<std::string> HttpExposureWarnings(const HttpServerOptions& opt, const std::string& http,
                                              const std::string& served, const std::string& exposed) {
  std::vector<std::string> out;
  if (IsLoopbackAddress(opt.address)) return out;
  if (opt.bearer_token.empty())
    out.push_back(
        "warning: --http " + http + " serves " + served +
        " to anyone who can reach this address, without authentication; give --http-token-file FILE "
        "(docs/distributed/monitoring.md#access-control)");
  else if (opt.tls_cert_file.empty())
    out.push_back("warning: --http " + http +
                  " with --http-token-file but without --http-tls-cert/--http-tls-key: the token and " +
                  exposed +
                  " cross the network in clear text; give a certificate and key "
                  "(docs/distributed/monitoring.md#https)");
  return out;
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

Status ParseHttpAddress(const std::string& text, HttpServerOptions* opt) {
  const size_t colon = text.rfind(':');
  if (colon == std::string::npos)
    return Status(ErrorCode::kInvalidArgument,
                  "--http " + text + ": expected HOST:PORT, e.g. 127.0.0.1:8080");
  std::string host = text.substr(0, colon);
  const std::string port = text.substr(colon + 1);
  if (host == "localhost") host = "127.0.0.1";
  if (host.empty()) host = "0.0.0.0";  // ":9101", as Prometheus exporters' listen addresses
  in_addr a{};
  if (::inet_pton(AF_INET, host.c_str(), &a) != 1)
    return Status(ErrorCode::kInvalidArgument,
                  "--http " + text + ": host must be an IPv4 address, localhost or empty (every interface)");
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

namespace {
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

void HttpServer::Serve(int fd) {
  // OpenSSL writes with write(), which raises SIGPIPE on a socket the peer closed: never on this
  // thread (the error comes back as EPIPE instead).
  {
    sigset_t pipe_set;
    sigemptyset(&pipe_set);
    sigaddset(&pipe_set, SIGPIPE);
    ::pthread_sigmask(SIG_BLOCK, &pipe_set, nullptr);
  }
  ::fcntl(fd, F_SETFD, FD_CLOEXEC);  // httplib's accept() does not ask for it
  const int flags = ::fcntl(fd, F_GETFL, 0);
  ::fcntl(fd, F_SETFL, (flags < 0 ? 0 : flags) | O_NONBLOCK);
  sockaddr_in peer{};
  socklen_t peer_len = sizeof peer;
  ::getpeername(fd, reinterpret_cast<sockaddr*>(&peer), &peer_len);
  char ip[INET_ADDRSTRLEN] = "?";
  ::inet_ntop(AF_INET, &peer.sin_addr, ip, sizeof ip);
  const std::string peer_text = std::string(ip) + ":" + std::to_string(ntohs(peer.sin_port));
  Conn c;
  c.fd = fd;
  c.wake_fd = wake_[0];
  c.deadline = Clock::now() + opt_.timeout;

  // The connection caps (in all, and per peer address), which httplib does not have: checked as
  // soon as the connection is accepted (a thread per connection, see ThreadPerConnection).
  {
    std::unique_lock<std::mutex> lock(peers_->mu);
    const int from_peer = int(peers_->open.count(peer.sin_addr.s_addr));
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
      c.Close();
      return;
    }
    peers_->open.insert(peer.sin_addr.s_addr);
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

  // TLS: the handshake under the connection's deadline (httplib's SSLServer cannot say why one
  // failed, nor answer plain HTTP sent to the port).
  if (tls_) {
    ERR_clear_error();
    c.ssl.reset(SSL_new(tls_->ctx.get()));
    if (!c.ssl || SSL_set_fd(c.ssl.get(), fd) != 1) {
      ERR_clear_error();
      ++dropped_;
      c.ssl.reset();
      c.Close();
      return;
    }
    SSL_set_accept_state(c.ssl.get());
    for (;;) {
      ERR_clear_error();
      const int r = SSL_accept(c.ssl.get());
      if (r == 1) break;
      const int e = SSL_get_error(c.ssl.get(), r);
      if (e == SSL_ERROR_WANT_READ || e == SSL_ERROR_WANT_WRITE) {
        if (c.Wait(e == SSL_ERROR_WANT_READ ? POLLIN : POLLOUT)) continue;
        if (c.timed_out) ++bad_;  // a silent or slow client
        c.ssl.reset();
        c.Close();
        return;
      }
      // Failed: counted and logged unless the peer sent nothing at all (a port check); plain HTTP
      // sent to the port gets a plain 400 that says to use https://.
      const unsigned long first = ERR_peek_error();
      const bool plain_http =
          ERR_GET_LIB(first) == ERR_LIB_SSL && ERR_GET_REASON(first) == SSL_R_HTTP_REQUEST;
      const std::string why = e == SSL_ERROR_SYSCALL && first == 0 ? "connection closed" : OpenSslReasons();
      ERR_clear_error();
      const bool sent_nothing = BIO_number_read(SSL_get_rbio(c.ssl.get())) == 0;
      c.ssl.reset();
      if (!sent_nothing) {
        ++tls_failed_;
        Log("http: TLS handshake with " + peer_text +
            " failed: " + (plain_http ? std::string("plain HTTP sent to the HTTPS port") : why));
        if (plain_http) {
          const std::string bytes =
              Serialize(Error(400, "this port speaks HTTPS only: use https:// instead of http://"), false);
          (void)::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
        }
      }
      c.Close();
      return;
    }
  }

  // The request head, read here rather than by httplib: bounded in size (431; httplib's limits are
  // per line, 8 KiB) and in time (408 at the deadline, for the whole head).
  std::string in;
  size_t end = std::string::npos;
  for (;;) {
    // A TLS ClientHello (a handshake record, version 3.x) to a plain port: refused at once rather
    // than at the timeout, so that an https:// client hears at once that this is not TLS.
    if (!c.ssl && in.size() >= 2 && in[0] == '\x16' && in[1] == '\x03') {
      ++bad_;
      respond(Error(400, "this port speaks plain HTTP, not TLS: use http://"), false);
      return;
    }
    end = in.find("\r\n\r\n");
    if (end == std::string::npos) end = in.find("\n\n");
    if ((end == std::string::npos && in.size() > opt_.max_head_bytes) ||
        (end != std::string::npos && end > opt_.max_head_bytes)) {
      ++bad_;
      respond(Error(431, "request head over " + std::to_string(opt_.max_head_bytes) + " bytes"), false);
      return;
    }
    if (end != std::string::npos) break;
    char buf[4096];
    const ssize_t n = c.Read(buf, sizeof buf);
    if (n > 0) {
      in.append(buf, size_t(n));
      continue;
    }
    if (n < 0 && c.timed_out) {
      // Slow client: one best-effort 408, then close.
      ++bad_;
      c.deadline = Clock::now() + std::chrono::milliseconds(100);
      respond(Error(408, "request not complete in time"), false);
      return;
    }
    c.Close();  // the peer went away, or the server stops
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
  // httplib wants CRLF line ends; the checks above also took bare LF ones.
  std::string head;
  for (size_t i = 0; i < end; ++i) {
    if (in[i] == '\n' && (i == 0 || in[i - 1] != '\r')) head += '\r';
    head += in[i];
  }
  head += "\r\n\r\n";
  ConnStream strm(&c, std::move(head), ip, ntohs(peer.sin_port));
  (void)httpd_->Process(strm, req);
  c.Close();
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

namespace {
/// The first certificate check that failed in this thread's HttpGet (X509_V_ERR_*; 0: none).
thread_local long g_verify_error = 0;

/// OpenSSL's certificate check callback of HttpGet's TLS context. httplib 0.11 makes its sessions
/// SSL_VERIFY_NONE and checks the certificate after the handshake, so a server would never hear
/// that its certificate was refused; on the first failed check this turns the session to
/// SSL_VERIFY_PEER, and OpenSSL ends the handshake with an alert (unknown CA, bad certificate)
/// that the server counts and logs (HttpServer::tls_handshake_failures).
int RefuseInHandshake(int ok, X509_STORE_CTX* store) {
  if (!ok) {
    if (g_verify_error == 0) g_verify_error = X509_STORE_CTX_get_error(store);
    SSL* ssl = static_cast<SSL*>(X509_STORE_CTX_get_ex_data(store, SSL_get_ex_data_X509_STORE_CTX_idx()));
    if (ssl) SSL_set_verify(ssl, SSL_VERIFY_PEER, nullptr);
  }
  return ok;
}
}  // namespace

Result<std::string> HttpGet(const std::string& url, std::chrono::milliseconds timeout,
                            const std::string& bearer_token, const std::string& ca_file) {
  auto parsed = ParseUrl(url);
  if (!parsed.ok()) return parsed.status();
  const ParsedUrl& u = *parsed;
  if (!ca_file.empty() && !u.tls)
    return Status(ErrorCode::kInvalidArgument, url + ": --http-ca-file is for https:// URLs");
  in_addr literal{};
  const bool ip_literal = ::inet_pton(AF_INET, u.host.c_str(), &literal) == 1;
  std::unique_ptr<httplib::ClientImpl> cli;
  httplib::SSLClient* ssl = nullptr;
  if (u.tls) {
    // A bad CA file is an error at once, naming it.
    if (!ca_file.empty()) POSEFOREST_RETURN_IF_ERROR(CheckHttpCaFile(ca_file));
    auto s = std::make_unique<httplib::SSLClient>(u.host, u.port);
    ssl = s.get();
    cli = std::move(s);
    SSL_CTX* ctx = ssl->ssl_context();
    if (!ctx)
      return Status(ErrorCode::kInternal, url + ": TLS: cannot create a context: " + OpenSslReasons());
    SSL_CTX_set_min_proto_version(ctx, TLS1_2_VERSION);
    SSL_CTX_set_options(ctx, SSL_OP_NO_RENEGOTIATION);
    // The certificate must chain to ca_file (empty: the system's trust store) and name the host
    // (DNS name or IP address), both checked by OpenSSL during the handshake (RefuseInHandshake)
    // and again by httplib after it.
    SSL_CTX_set_verify(ctx, SSL_VERIFY_PEER, RefuseInHandshake);
    X509_VERIFY_PARAM* param = SSL_CTX_get0_param(ctx);
    if (ip_literal)
      X509_VERIFY_PARAM_set1_ip_asc(param, u.host.c_str());
    else
      X509_VERIFY_PARAM_set1_host(param, u.host.c_str(), 0);
    if (!ca_file.empty()) ssl->set_ca_cert_path(ca_file.c_str());
    ssl->enable_server_certificate_verification(true);
  } else {
    cli = std::make_unique<httplib::ClientImpl>(u.host, u.port);
  }
  cli->set_address_family(AF_INET);
  cli->set_connection_timeout(timeout);
  cli->set_read_timeout(timeout);
  cli->set_write_timeout(timeout);
  httplib::Headers headers;
  if (!bearer_token.empty()) headers.emplace("Authorization", "Bearer " + bearer_token);
  std::string body;
  bool too_big = false;
  SigpipeBlock no_sigpipe;  // OpenSSL's write() to a closed socket
  ERR_clear_error();
  g_verify_error = 0;
  const httplib::Result res = cli->Get(u.path, headers, [&](const char* data, size_t n) {
    if (body.size() + n > (size_t(64) << 20)) {
      too_big = true;
      return false;
    }
    body.append(data, n);
    return true;
  });
  if (too_big) return Status(ErrorCode::kDataLoss, url + ": reply over 64 MiB");
  if (!res) {
    const httplib::Error e = res.error();
    switch (e) {
      case httplib::Error::SSLServerVerification:  // checked after the handshake: a name CN only
        if (g_verify_error == 0)
          g_verify_error = ip_literal ? X509_V_ERR_IP_ADDRESS_MISMATCH : X509_V_ERR_HOSTNAME_MISMATCH;
        break;
      default:
        break;
    }
    if (g_verify_error != 0) {
      ERR_clear_error();
      const std::string why = X509_verify_cert_error_string(g_verify_error);
      if (g_verify_error == X509_V_ERR_HOSTNAME_MISMATCH || g_verify_error == X509_V_ERR_IP_ADDRESS_MISMATCH)
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
    switch (e) {
      case httplib::Error::SSLConnection: {
        const unsigned long first = ERR_peek_error();
        if (first == 0)
          return Status(ErrorCode::kIo, url + ": the TLS handshake did not complete (closed or timed out)");
        const bool plain =
            ERR_GET_LIB(first) == ERR_LIB_SSL && (ERR_GET_REASON(first) == SSL_R_WRONG_VERSION_NUMBER ||
                                                  ERR_GET_REASON(first) == SSL_R_PACKET_LENGTH_TOO_LONG);
        return Status(ErrorCode::kInvalidArgument,
                      url + ": TLS handshake failed (" + OpenSslReasons() + ")" +
                          (plain ? "; the server does not speak TLS: is it http://?" : ""));
      }
      case httplib::Error::SSLLoadingCerts:
        return Status(ErrorCode::kInvalidArgument,
                      (ca_file.empty() ? url + ": the system's trust store" : "--http-ca-file " + ca_file) +
                          ": cannot be loaded: " + OpenSslReasons());
      case httplib::Error::Connection:
        return Status(ErrorCode::kIo, url + ": cannot connect (refused, unreachable or no such host)");
      case httplib::Error::ConnectionTimeout:
        return Status(ErrorCode::kIo, url + ": connect timed out");
      case httplib::Error::Read:
        return Status(ErrorCode::kIo, url + ": no complete HTTP reply (timed out, truncated, or not HTTP)");
      case httplib::Error::Write:
        return Status(ErrorCode::kIo, url + ": cannot send the request");
      default:
        return Status(ErrorCode::kIo, url + ": " + httplib::to_string(e));
    }
  }
  const int code = res->status;
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

}  // namespace poseforest::proto::http
