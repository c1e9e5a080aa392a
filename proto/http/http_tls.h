#pragma once
// OpenSSL for the HTTP server and client (http_server.cpp, http_client.cpp): owning pointers,
// error text, the checked reading of secret and certificate files, the server's TLS context.
// Internal to proto/http (OpenSSL stays out of http_server.h).

#include <openssl/ssl.h>
#include <openssl/x509.h>

#include <memory>
#include <string>

#include "runtime/core/result.h"

namespace poseforest::proto::http::detail {

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
std::string OpenSslReasons();

/// The bytes of `path`, read through one open file (no race between the checks and the read;
/// symlinks are followed: a Kubernetes Secret's files are symlinks): a regular file of at most
/// `max_bytes` (else the error `too_big`); with `secret`, no access for others nor, unless root
/// owns it, for its group (ssh's rule for a private key). Errors start with `what`.
core::Result<std::string> ReadCheckedFile(const std::string& path, const std::string& what, bool secret,
                                          size_t max_bytes, const std::string& too_big);

/// OpenSSL's server context for `cert_file` (PEM chain) and `key_file` (PEM key): TLS 1.2+.
core::Result<SslCtxPtr> MakeServerContext(const std::string& cert_file, const std::string& key_file);

}  // namespace poseforest::proto::http::detail
