#pragma once
// The checks the HTTP server makes on a request before cpp-httplib sees it (http_server.cpp):
// the request line, the presented bearer token; and the replies it writes itself. Internal to
// proto/http.

#include <string>

#include "proto/http/http_server.h"

namespace poseforest::proto::http::detail {

/// The reply's bytes: status line, headers (no caching, "Connection: close", `extra_headers`:
/// "Name: value\r\n" lines), then the body unless `head_only`.
std::string Serialize(const HttpResponse& r, bool head_only, const std::string& extra_headers = "");

/// A plain-text error reply: "STATUS Reason: why".
HttpResponse Error(int status, const std::string& why);

/// The request line of `head` into req (method, path, query), strictly: false with the reply in
/// `error` (400 malformed, 405 not GET or HEAD).
bool ParseHead(const std::string& head, HttpRequest* req, HttpResponse* error);

/// The credentials a request presents: the bearer token of its Authorization header, or for the
/// dashboard page its `token` query parameter. `present` says whether it tried at all.
std::string PresentedToken(const std::string& head, const HttpRequest& req, bool* present, bool* ambiguous);

}  // namespace poseforest::proto::http::detail
