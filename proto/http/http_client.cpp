#include <arpa/inet.h>
#include <netinet/in.h>
#include <openssl/err.h>
#include <openssl/x509v3.h>
#include <pthread.h>
#include <signal.h>

#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <memory>

// cpp-httplib with its OpenSSL support (CPPHTTPLIB_OPENSSL_SUPPORT comes with the pkg-config target).
#include <httplib.h>

#include "proto/http/http_server.h"
#include "proto/http/http_tls.h"

// The client side: HttpGet (`poseforest monitor`).

namespace poseforest::proto::http {

using core::ErrorCode;
using core::Result;
using core::Status;
using detail::OpenSslReasons;

namespace {

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

/// HttpGet's TLS settings on `ssl`'s context (CheckHttpCaFile first when ca_file is given).
Status ConfigureClientTls(httplib::SSLClient* ssl, const ParsedUrl& u, bool ip_literal, const std::string& url,
                          const std::string& ca_file) {
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
  return Status::Ok();
}

/// Why HttpGet got no reply (httplib's error `e`, and the certificate check's in g_verify_error).
Status RequestFailure(httplib::Error e, const ParsedUrl& u, bool ip_literal, const std::string& url,
                      const std::string& ca_file) {
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

/// The error of a reply other than 200 (`body` its body).
Status ReplyFailure(int code, const std::string& body, const std::string& url, const std::string& bearer_token) {
  if (code == 401)
    return Status(
        ErrorCode::kInvalidArgument,
        url + ": HTTP 401: " + body.substr(0, body.find('\n')) +
            (bearer_token.empty() ? " (the coordinator has --http-token-file: pass the same token file)"
                                  : " (the token sent is not the coordinator's)"));
  return Status(code == 404 ? ErrorCode::kNotFound
                : code == 400
                    ? ErrorCode::kInvalidArgument  // e.g. http:// to an HTTPS port: retrying will not help
                    : ErrorCode::kIo,
                url + ": HTTP " + std::to_string(code) + ": " + body.substr(0, body.find('\n')));
}

}  // namespace

Status CheckHttpUrl(const std::string& url) { return ParseUrl(url).status(); }

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
  if (u.tls) {
    // A bad CA file is an error at once, naming it.
    if (!ca_file.empty()) POSEFOREST_RETURN_IF_ERROR(CheckHttpCaFile(ca_file));
    auto s = std::make_unique<httplib::SSLClient>(u.host, u.port);
    httplib::SSLClient* ssl = s.get();
    cli = std::move(s);
    POSEFOREST_RETURN_IF_ERROR(ConfigureClientTls(ssl, u, ip_literal, url, ca_file));
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
  if (!res) return RequestFailure(res.error(), u, ip_literal, url, ca_file);
  const int code = res->status;
  if (code != 200) return ReplyFailure(code, body, url, bearer_token);
  return body;
}

}  // namespace poseforest::proto::http
