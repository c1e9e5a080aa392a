#include "proto/http/http_connection.h"

#include <fcntl.h>
#include <pthread.h>
#include <signal.h>

namespace poseforest::proto::http::detail {

std::string PreparePeer(int fd, sockaddr_in* peer, char (&ip)[INET_ADDRSTRLEN]) {
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
  socklen_t peer_len = sizeof *peer;
  ::getpeername(fd, reinterpret_cast<sockaddr*>(peer), &peer_len);
  ::inet_ntop(AF_INET, &peer->sin_addr, ip, INET_ADDRSTRLEN);
  return std::string(ip) + ":" + std::to_string(ntohs(peer->sin_port));
}

Handshake TlsAccept(Conn& c, SSL_CTX* ctx, int fd) {
  Handshake hs;
  ERR_clear_error();
  c.ssl.reset(SSL_new(ctx));
  if (!c.ssl || SSL_set_fd(c.ssl.get(), fd) != 1) {
    ERR_clear_error();
    c.ssl.reset();
    hs.outcome = Handshake::kNoSession;
    return hs;
  }
  SSL_set_accept_state(c.ssl.get());
  for (;;) {
    ERR_clear_error();
    const int r = SSL_accept(c.ssl.get());
    if (r == 1) return hs;
    const int e = SSL_get_error(c.ssl.get(), r);
    if (e == SSL_ERROR_WANT_READ || e == SSL_ERROR_WANT_WRITE) {
      if (c.Wait(e == SSL_ERROR_WANT_READ ? POLLIN : POLLOUT)) continue;
      c.ssl.reset();
      hs.outcome = Handshake::kWaitEnded;
      return hs;
    }
    // Failed: counted and logged unless the peer sent nothing at all (a port check); plain HTTP
    // sent to the port gets a plain 400 that says to use https://.
    const unsigned long first = ERR_peek_error();
    hs.plain_http = ERR_GET_LIB(first) == ERR_LIB_SSL && ERR_GET_REASON(first) == SSL_R_HTTP_REQUEST;
    hs.why = e == SSL_ERROR_SYSCALL && first == 0 ? "connection closed" : OpenSslReasons();
    ERR_clear_error();
    hs.sent_nothing = BIO_number_read(SSL_get_rbio(c.ssl.get())) == 0;
    c.ssl.reset();
    hs.outcome = Handshake::kFailed;
    return hs;
  }
}

HeadRead ReadHead(Conn& c, size_t max_head_bytes, std::string& in, size_t* end_out) {
  size_t end = std::string::npos;
  for (;;) {
    // A TLS ClientHello (a handshake record, version 3.x) to a plain port: refused at once rather
    // than at the timeout, so that an https:// client hears at once that this is not TLS.
    if (!c.ssl && in.size() >= 2 && in[0] == '\x16' && in[1] == '\x03') return HeadRead::kTlsOnPlainPort;
    end = in.find("\r\n\r\n");
    if (end == std::string::npos) end = in.find("\n\n");
    if ((end == std::string::npos && in.size() > max_head_bytes) ||
        (end != std::string::npos && end > max_head_bytes))
      return HeadRead::kTooLarge;
    if (end != std::string::npos) break;
    char buf[4096];
    const ssize_t n = c.Read(buf, sizeof buf);
    if (n > 0) {
      in.append(buf, size_t(n));
      continue;
    }
    if (n < 0 && c.timed_out) return HeadRead::kTimedOut;
    return HeadRead::kGone;  // the peer went away, or the server stops
  }
  *end_out = end;
  return HeadRead::kOk;
}

std::string CrlfHead(const std::string& in, size_t end) {
  std::string head;
  for (size_t i = 0; i < end; ++i) {
    if (in[i] == '\n' && (i == 0 || in[i - 1] != '\r')) head += '\r';
    head += in[i];
  }
  head += "\r\n\r\n";
  return head;
}

}  // namespace poseforest::proto::http::detail
