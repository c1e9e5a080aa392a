#include "proto/http/http_tls.h"

#include <fcntl.h>
#include <openssl/crypto.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/x509v3.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "proto/http/http_server.h"

// The files the HTTP server and client read: TLS certificate and key, CA certificates, the
// bearer token; and the server's TLS context made from them.

namespace poseforest::proto::http {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace detail {

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

namespace {

std::string Asn1TimeText(const ASN1_TIME* t) {
  BioPtr b(BIO_new(BIO_s_mem()));
  if (!b || ASN1_TIME_print(b.get(), t) != 1) return "?";
  char* data = nullptr;
  const long n = BIO_get_mem_data(b.get(), &data);
  return n > 0 ? std::string(data, size_t(n)) : "?";
}

}  // namespace

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

namespace {

/// A private key's PEM text is wiped from memory when this goes.
struct WipedString {
  std::string text;
  ~WipedString() {
    if (!text.empty()) OPENSSL_cleanse(text.data(), text.size());
  }
};

int NoPassphrase(char*, int, int, void*) { return -1; }  // never prompt on a terminal

}  // namespace

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

}  // namespace detail

using detail::BioPtr;
using detail::MakeServerContext;
using detail::OpenSslReasons;
using detail::ReadCheckedFile;
using detail::X509Ptr;

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

}  // namespace poseforest::proto::http
