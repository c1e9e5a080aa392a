#include "proto/http/http_request.h"

#include <arpa/inet.h>
#include <netinet/in.h>

#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <sstream>
#include <vector>

// The request checks before cpp-httplib (http_request.h), and the address, exposure and token
// helpers of http_server.h.

namespace poseforest::proto::http {

using core::ErrorCode;
using core::Status;

namespace detail {
namespace {

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

bool IsTokenChar(char c) {
  return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' || c == '_';
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

}  // namespace

std::string Serialize(const HttpResponse& r, bool head_only, const std::string& extra_headers) {
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

}  // namespace detail

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

}  // namespace poseforest::proto::http
