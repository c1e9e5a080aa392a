// Access control of the coordinator's HTTP status server (`--http-token-file`): every endpoint but
// /healthz (open, for probes) refuses requests without the bearer token (401, WWW-Authenticate, nothing
// leaked, counted, logged with the peer, rate-limited), takes the right token in the Authorization header
// (and in ?token= for the dashboard page only), serves the same bytes as a server without a token; the token
// file checks (missing, empty, mode, content); the per-peer connection cap; the real `poseforest coordinator`
// and `monitor` with a token file, the start-up warnings for a non-loopback address without one (and with one
// but without TLS); the dashboard in headless Chromium opened with ?token= (and a wrong token, which must
// show no data). docs/distributed/monitoring.md#access-control.

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <regex>
#include <sstream>
#include <thread>

#include "coordinator/monitoring/dashboard.h"
#include "coordinator/monitoring/status_model.h"
#include "proto/http/http_server.h"
#include "tests/coordinator/dist_test_util.h"
#include "tests/coordinator/http_test_util.h"
#include "tests/proto/dds_test_util.h"
#include "tests/support/process.h"

using namespace poseforest;
using namespace poseforest::proto::http;
using namespace poseforest::coordinator::monitoring;
using namespace poseforest::coordinator::testing;
using poseforest::proto::dds::testing::Child;
using poseforest::proto::dds::testing::HelperDir;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {
std::string Program() { return (HelperDir() / "poseforest").string(); }

std::string Head(const std::string& reply) { return reply.substr(0, reply.find("\r\n\r\n") + 2); }
std::string Body(const std::string& reply) {
  const size_t p = reply.find("\r\n\r\n");
  return p == std::string::npos ? "" : reply.substr(p + 4);
}

std::string Get(const std::string& target, const std::string& headers = "") {
  return "GET " + target + " HTTP/1.1\r\nHost: x\r\n" + headers + "\r\n";
}

/// A file holding `text` with `mode`.
fs::path WriteFile(const fs::path& p, const std::string& text, mode_t mode) {
  std::ofstream(p, std::ios::binary) << text;
  REQUIRE(::chmod(p.c_str(), mode) == 0);
  return p;
}

/// `text` without its "now_unix" field (the one figure of a finished job's JSON that moves).
std::string WithoutNow(const std::string& text) {
  const std::string out = std::regex_replace(text, std::regex(R"("now_unix":[-0-9.e+]+,)"), "");
  CHECK(out.size() < text.size());
  return out;
}

const char* const kToken = "Zq3+tok/en_0123456789abcdef.~=";  // '+', '/', '=' as base64 has them
const char* const kBody401 = "401 Unauthorized: a bearer token is required\n";
}  // namespace

TEST_CASE(
    "HTTP bearer token: every endpoint but /healthz refuses without it, the right one gets the same bytes",
    "[distributed][monitoring][http][unit]") {
  StatusModel model({"auth-job", 3, "shm", 2, 6, 10, 100, 20, 8, "/tmp/x.pff"});
  model.Finish(true, "wrote /tmp/x.pff");  // a final state: its JSON no longer changes
  LogLines log_lines;
  HttpServerOptions opt;
  opt.bearer_token = kToken;
  opt.log_burst = 3;
  opt.log_interval = 3600s;  // no refill during the test
  opt.log = log_lines.Sink();
  auto secured = HttpServer::Start(opt, StatusHandler(&model));
  REQUIRE(secured.ok());
  auto open = HttpServer::Start(HttpServerOptions{}, StatusHandler(&model));  // no token: as before
  REQUIRE(open.ok());
  const uint16_t port = (*secured)->port();
  const std::string token = kToken;
  const std::string bearer = "Authorization: Bearer " + token + "\r\n";

  int refused = 0;
  auto refuse = [&](const std::string& request, bool invalid_token) {
    INFO(request);
    const std::string r = RawExchange(port, request);
    CHECK(StatusCode(r) == 401);
    CHECK(Head(r).find("\r\nWWW-Authenticate: Bearer realm=\"poseforest\"" +
                       std::string(invalid_token ? ", error=\"invalid_token\"" : "") + "\r\n") !=
          std::string::npos);
    if (request.rfind("HEAD", 0) == 0)
      CHECK(Body(r).empty());
    else
      CHECK(Body(r) == kBody401);  // nothing else: no job, no path, no hint of the token
    CHECK(r.find("auth-job") == std::string::npos);
    ++refused;
  };
  const std::vector<std::string> endpoints = {"/",        "/index.html", "/status.json", "/metrics",
                                              "/nothing", "/healthz/x",  "/healthz.json"};
  for (const std::string& e : endpoints) {
    refuse(Get(e), false);                                                                     // no token
    refuse(Get(e, "Authorization: Bearer " + std::string(token.size(), 'x') + "\r\n"), true);  // same length
    refuse(Get(e, "Authorization: Bearer " + token.substr(0, token.size() - 1) + "\r\n"), true);  // prefix
    refuse(Get(e, "Authorization: Bearer " + token + "x\r\n"), true);                             // longer
    refuse(Get(e, "Authorization: Bearer \r\n"), true);                                           // empty
    refuse(Get(e, "Authorization: Basic " + token + "\r\n"), true);      // another scheme
    refuse(Get(e, "Authorization: " + token + "\r\n"), true);            // no scheme
    refuse(Get(e, bearer + "Authorization: Bearer wrong\r\n"), true);    // two headers
    refuse(Get(e, "X-Authorization: Bearer " + token + "\r\n"), false);  // not the header
  }
  refuse("HEAD /metrics HTTP/1.1\r\n\r\n", false);
  // ?token= is for the dashboard page only; never for the data.
  refuse(Get("/status.json?token=" + token), false);
  refuse(Get("/metrics?token=" + token), false);
  refuse(Get("/?token=" + std::string(token.size(), 'y')), true);
  refuse(Get("/?tok=" + token), false);

  // /healthz alone is open (liveness and readiness probes carry no secret): 200 "ok" with no token,
  // a wrong one or a query, by GET and HEAD; not counted as refused, nothing else in the reply.
  for (const std::string& h : {std::string(""), std::string("Authorization: Bearer wrong\r\n")})
    for (const std::string& target : {std::string("/healthz"), std::string("/healthz?token=x")}) {
      INFO(target << " " << h);
      const std::string r = RawExchange(port, Get(target, h));
      CHECK(StatusCode(r) == 200);
      CHECK(Body(r) == "ok\n");
      CHECK(Head(r).find("WWW-Authenticate") == std::string::npos);
    }
  CHECK(StatusCode(RawExchange(port, "HEAD /healthz HTTP/1.1\r\n\r\n")) == 200);

  // The right token: 200 everywhere, the same bytes as the server without a token.
  for (const std::string& e :
       {std::string("/"), std::string("/index.html"), std::string("/status.json"), std::string("/healthz")}) {
    INFO(e);
    const std::string with = RawExchange(port, Get(e, bearer));
    const std::string without = RawExchange((*open)->port(), Get(e));
    CHECK(StatusCode(with) == 200);
    CHECK(StatusCode(without) == 200);
    CHECK((e == "/status.json" ? WithoutNow(Body(with)) : Body(with)) ==
          (e == "/status.json" ? WithoutNow(Body(without)) : Body(without)));
    CHECK(Head(with).find("WWW-Authenticate") == std::string::npos);
  }
  CHECK(StatusCode(RawExchange(port, Get("/nothing", bearer))) == 404);
  CHECK(StatusCode(RawExchange(port, Get("/status.json", "authorization:   bearer   " + token + "  \r\n"))) ==
        200);
  CHECK(StatusCode(RawExchange(port, Get("/?token=" + token))) == 200);
  std::string encoded;  // the same token percent-encoded, as a browser may send it
  for (char c : token) {
    char buf[4];
    std::snprintf(buf, sizeof buf, "%%%02X", unsigned(static_cast<unsigned char>(c)));
    encoded += buf;
  }
  CHECK(StatusCode(RawExchange(port, Get("/index.html?x=1&token=" + encoded))) == 200);
  auto json = HttpGet((*secured)->url() + "/status.json", 2s, token);
  REQUIRE(json.ok());
  auto plain = HttpGet((*open)->url() + "/status.json", 2s);
  REQUIRE(plain.ok());
  CHECK(WithoutNow(*json) == WithoutNow(*plain));
  CHECK(json->find("\"job_id\":\"auth-job\"") != std::string::npos);

  // The client names the problem.
  auto none = HttpGet((*secured)->url() + "/status.json", 2s);
  REQUIRE(!none.ok());
  CHECK(none.status().message().find("HTTP 401") != std::string::npos);
  CHECK(none.status().message().find("--http-token-file") != std::string::npos);
  auto wrong = HttpGet((*secured)->url() + "/status.json", 2s, "not-the-token");
  REQUIRE(!wrong.ok());
  CHECK(wrong.status().message().find("not the coordinator's") != std::string::npos);
  refused += 2;

  // Counted: in the server and in /metrics (read with the token).
  std::this_thread::sleep_for(100ms);
  CHECK((*secured)->unauthorized() == uint64_t(refused));
  auto metrics = HttpGet((*secured)->url() + "/metrics", 2s, token);
  REQUIRE(metrics.ok());
  CHECK(metrics->find("# TYPE poseforest_http_requests_total counter") != std::string::npos);
  CHECK(metrics->find("poseforest_http_requests_total{outcome=\"unauthorized\"} " + std::to_string(refused) +
                      "\n") != std::string::npos);
  CHECK(std::regex_search(*metrics, std::regex(R"(poseforest_http_requests_total\{outcome="ok"\} [1-9])")));
  CHECK(metrics->find("poseforest_http_requests_total{outcome=\"bad_request\"} 0\n") != std::string::npos);
  // Logged with the peer address, rate-limited (burst 3, no refill), never with a token.
  const std::vector<std::string> log = log_lines.Lines();
  INFO(log_lines.Joined());
  REQUIRE(log.size() == 3);
  CHECK(std::regex_match(log[0], std::regex(R"(http: 401 for GET / from 127\.0\.0\.1:[0-9]+: no token)")));
  CHECK(std::regex_match(log[1], std::regex(R"(http: 401 for GET / from 127\.0\.0\.1:[0-9]+: wrong token)")));
  for (const auto& l : log) CHECK(l.find("xxxx") == std::string::npos);
}

TEST_CASE("HTTP refusal log: a burst, then one line per interval saying how many were left out",
          "[distributed][monitoring][http][unit]") {
  StatusModel model({"log-job", 3, "shm", 2, 6, 10, 100, 20, 8, ""});
  LogLines log_lines;
  HttpServerOptions opt;
  opt.bearer_token = "t0k3n-of-the-test";
  opt.log_burst = 1;
  opt.log_interval = 400ms;
  opt.log = log_lines.Sink();
  auto server = HttpServer::Start(opt, StatusHandler(&model));
  REQUIRE(server.ok());
  for (int i = 0; i < 6; ++i) CHECK(StatusCode(RawExchange((*server)->port(), Get("/metrics"))) == 401);
  std::this_thread::sleep_for(600ms);
  CHECK(StatusCode(RawExchange((*server)->port(), Get("/"))) == 401);
  std::this_thread::sleep_for(100ms);
  const std::vector<std::string> log = log_lines.Lines();
  REQUIRE(log.size() == 2);
  CHECK(log[0].find("401 for GET /metrics from 127.0.0.1:") == 0 + log[0].find("401"));
  CHECK(std::regex_search(log[1], std::regex("GET / from ")));
  CHECK(log[1].find("(5 more refused requests not logged)") != std::string::npos);
  CHECK((*server)->unauthorized() == 7);
}

TEST_CASE("constant-time token comparison", "[distributed][monitoring][http][unit]") {
  CHECK(ConstantTimeEquals("abc", "abc"));
  CHECK_FALSE(ConstantTimeEquals("abd", "abc"));
  CHECK_FALSE(ConstantTimeEquals("ab", "abc"));
  CHECK_FALSE(ConstantTimeEquals("abcabc", "abc"));  // the secret repeated is not the secret
  CHECK_FALSE(ConstantTimeEquals("", "abc"));
  CHECK_FALSE(ConstantTimeEquals(std::string("abc\0", 4), "abc"));
  CHECK(IsLoopbackAddress("127.0.0.1"));
  CHECK(IsLoopbackAddress("127.1.2.3"));
  CHECK_FALSE(IsLoopbackAddress("0.0.0.0"));
  CHECK_FALSE(IsLoopbackAddress("10.0.0.1"));
}

TEST_CASE("HTTP token file: missing, empty, too open, bad content are refused naming the file",
          "[distributed][monitoring][http][unit]") {
  TempDir dir("pf-http-token");
  auto error = [](const fs::path& p) {
    auto r = ReadHttpTokenFile(p.string());
    INFO(p.string());
    REQUIRE(!r.ok());
    CHECK(r.status().message().find("--http-token-file " + p.string()) == 0);
    return r.status().message();
  };
  CHECK(error(dir.path / "missing").find("No such file") != std::string::npos);
  CHECK(error(dir.path).find("not a regular file") != std::string::npos);
  CHECK(error(WriteFile(dir.path / "empty", "", 0600)).find("empty") != std::string::npos);
  CHECK(error(WriteFile(dir.path / "newline", "\n", 0600)).find("empty") != std::string::npos);
  CHECK(error(WriteFile(dir.path / "crlf", "\r\n", 0600)).find("empty") != std::string::npos);
  CHECK(error(WriteFile(dir.path / "two-lines", "abc\n\n", 0600)).find("byte 3") != std::string::npos);
  CHECK(error(WriteFile(dir.path / "space", "ab c\n", 0600)).find("byte 2") != std::string::npos);
  CHECK(error(WriteFile(dir.path / "utf8", "ab\xc3\xa9", 0600)).find("byte 2") != std::string::npos);
  CHECK(error(WriteFile(dir.path / "huge", std::string(5000, 'a'), 0600)).find("4096") != std::string::npos);
  // Permissions, like ssh's check of a private key.
  const std::string open_msg = error(WriteFile(dir.path / "world", "secret\n", 0644));
  CHECK(open_msg.find("permissions 0644 are too open") != std::string::npos);
  CHECK(open_msg.find("chmod 600 " + (dir.path / "world").string()) != std::string::npos);
  CHECK(error(WriteFile(dir.path / "others-only", "secret\n", 0604)).find("open to others") !=
        std::string::npos);
  CHECK(error(WriteFile(dir.path / "others-x", "secret\n", 0601)).find("open to others") !=
        std::string::npos);
  CHECK(error(WriteFile(dir.path / "group-write", "secret\n", 0620)).find("writable by its group") !=
        std::string::npos);
  // Group-readable: only when root owns it (a Kubernetes Secret with fsGroup: root:GROUP 0440).
  const fs::path group = WriteFile(dir.path / "group", "secret\n", 0640);
  if (::geteuid() == 0) {
    auto root_owned = ReadHttpTokenFile(group.string());
    REQUIRE(root_owned.ok());
    CHECK(*root_owned == "secret");
    REQUIRE(::chown(group.c_str(), 65534, 65534) == 0);  // owned by nobody: group-readable is too open
  }
  CHECK(error(group).find("readable by its group") != std::string::npos);
  // Good files: one trailing newline (LF or CRLF) dropped, a symlink followed (Secret mounts).
  auto ok = [](const fs::path& p) {
    auto r = ReadHttpTokenFile(p.string());
    INFO(p.string() << ": " << (r.ok() ? "" : r.status().message()));
    REQUIRE(r.ok());
    return *r;
  };
  CHECK(ok(WriteFile(dir.path / "plain", "abc", 0600)) == "abc");
  CHECK(ok(WriteFile(dir.path / "lf", "abc\n", 0400)) == "abc");
  CHECK(ok(WriteFile(dir.path / "crlf-ok", "abc\r\n", 0600)) == "abc");
  fs::create_symlink(dir.path / "lf", dir.path / "link");
  CHECK(ok(dir.path / "link") == "abc");
}

TEST_CASE("HTTP per-peer connection cap: one address cannot take every slot",
          "[distributed][monitoring][http][unit]") {
  StatusModel model({"cap-job", 3, "shm", 2, 6, 10, 100, 20, 8, ""});
  LogLines log_lines;
  HttpServerOptions opt;
  opt.max_connections = 8;
  opt.max_connections_per_peer = 3;
  opt.timeout = 3s;
  opt.log = log_lines.Sink();
  auto server = HttpServer::Start(opt, StatusHandler(&model));
  REQUIRE(server.ok());
  const uint16_t port = (*server)->port();
  // Three idle connections from 127.0.0.1 (connected, nothing sent).
  std::vector<int> idle;
  for (int i = 0; i < 3; ++i) {
    const int fd = ConnectLoopback(port);
    idle.push_back(fd);
  }
  std::this_thread::sleep_for(200ms);
  CHECK(StatusCode(RawExchange(port, Get("/healthz"), 5s, "127.0.0.1")) ==
        503);  // a fourth from the same address
  CHECK(StatusCode(RawExchange(port, Get("/healthz"), 5s, "127.0.0.2")) ==
        200);  // another address still gets in
  CHECK((*server)->dropped() == 1);
  for (int fd : idle) ::close(fd);
  std::this_thread::sleep_for(300ms);
  CHECK(StatusCode(RawExchange(port, Get("/healthz"), 5s, "127.0.0.1")) == 200);
  const std::vector<std::string> log = log_lines.Lines();
  REQUIRE(log.size() == 1);
  CHECK(std::regex_match(
      log[0],
      std::regex(
          R"(http: 503 for a connection from 127\.0\.0\.1:[0-9]+: 3 already open from that address)")));
}

TEST_CASE("coordinator and monitor with --http-token-file: real processes",
          "[distributed][monitoring][http][integration]") {
  TempDir dir("pf-http-auth-run");
  std::ofstream(dir.path / "job.textproto") << TinyJobText(1, 4);
  const std::string job = (dir.path / "job.textproto").string();
  const std::string out = (dir.path / "forest.pff").string();
  const fs::path token_file = WriteFile(dir.path / "token", std::string(kToken) + "\n", 0600);
  const fs::path loose = WriteFile(dir.path / "loose", std::string(kToken) + "\n", 0644);
  const fs::path empty = WriteFile(dir.path / "empty", "", 0600);
  const fs::path wrong = WriteFile(dir.path / "wrong", "not-the-token\n", 0600);

  // Bad token files: exit 2 naming the file, with and without --check-config, and through
  // `train --local-workers` (the same flags).
  for (const std::string& prefix :
       {"coordinator " + job + " --out " + out, "coordinator " + job + " --out " + out + " --check-config",
        "train " + job + " --out " + out + " --local-workers 1"}) {
    for (const fs::path& bad : {loose, empty, dir.path / "missing"}) {
      auto r = poseforest::testing::RunPoseforest(prefix + " --http-token-file " + bad.string());
      INFO(prefix << " / " << bad << ": " << r.output);
      CHECK(r.exit_code == 2);
      CHECK(r.output.find("--http-token-file " + bad.string() + ": ") != std::string::npos);
    }
  }
  {
    auto r = poseforest::testing::RunPoseforest("coordinator " + job + " --out " + out +
                                                " --http off --http-token-file " + token_file.string());
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK(r.output.find("--http off") != std::string::npos);
    auto ok = poseforest::testing::RunPoseforest("coordinator " + job + " --out " + out +
                                                 " --check-config --http-token-file " + token_file.string());
    INFO(ok.output);
    CHECK(ok.exit_code == 0);
  }
  {
    auto r = poseforest::testing::RunPoseforest("monitor --url http://127.0.0.1:1 --once --http-token-file " +
                                                loose.string());
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK(r.output.find("permissions 0644 are too open") != std::string::npos);
  }

  // A coordinator on every interface with a token (it waits for a worker that never comes):
  // no warning; every endpoint but /healthz wants the token; monitor with the file works, without it fails.
  Child coord;
  std::string error;
  REQUIRE(coord.Start(
      {Program(), "coordinator", job, "--out", out, "--domain", std::to_string(Domain(61)), "--min-workers",
       "1", "--worker-wait-s", "120", "--http", "0.0.0.0:0", "--http-token-file", token_file.string()},
      &error));
  auto line = coord.WaitForLine("status: http://", 60s);
  INFO(coord.output());
  REQUIRE(line.has_value());
  CHECK(line->find("--http-token-file " + token_file.string()) != std::string::npos);
  CHECK(coord.output().find(kToken) == std::string::npos);  // never printed
  // No warning about access without authentication; one about the token in clear text (plain HTTP
  // on every interface: test_https checks that it goes with --http-tls-cert/--http-tls-key).
  CHECK(coord.output().find("without authentication") == std::string::npos);
  CHECK(coord.output().find("coordinator: warning: --http 0.0.0.0:0 with --http-token-file but without "
                            "--http-tls-cert/--http-tls-key") != std::string::npos);
  const std::string url =
      line->substr(line->find("http://"), line->find("/ (dashboard)") - line->find("http://"));
  const uint16_t port = uint16_t(std::stoi(url.substr(url.rfind(':') + 1)));
  CHECK(StatusCode(RawExchange(port, Get("/healthz"))) == 200);
  for (const char* e : {"/", "/status.json", "/metrics"}) {
    INFO(e);
    CHECK(StatusCode(RawExchange(port, Get(e))) == 401);
    CHECK(StatusCode(RawExchange(port, Get(e, "Authorization: Bearer not-the-token\r\n"))) == 401);
    CHECK(StatusCode(RawExchange(port, Get(e, "Authorization: Bearer " + std::string(kToken) + "\r\n"))) ==
          200);
  }
  auto status = HttpGet(url + "/status.json", 5s, kToken);
  REQUIRE(status.ok());
  CHECK(status->find("\"state\":\"waiting\"") != std::string::npos);
  auto mon = poseforest::testing::RunPoseforest("monitor --once --url " + url + " --http-token-file " +
                                                token_file.string());
  INFO(mon.output);
  CHECK(mon.exit_code == 0);
  CHECK(mon.output.find("state waiting") != std::string::npos);
  auto mon_none = poseforest::testing::RunPoseforest("monitor --url " + url + " --timeout-s 60");
  INFO(mon_none.output);
  CHECK(mon_none.exit_code == 1);  // at once on 401, not after the timeout
  CHECK(mon_none.output.find("HTTP 401") != std::string::npos);
  auto mon_wrong = poseforest::testing::RunPoseforest("monitor --once --url " + url + " --http-token-file " +
                                                      wrong.string());
  INFO(mon_wrong.output);
  CHECK(mon_wrong.exit_code == 1);
  CHECK(mon_wrong.output.find("not the coordinator's") != std::string::npos);
  // The refusals are in the coordinator's log, with the peer.
  auto logged = coord.WaitForLine("http: 401 for GET ", 10s);
  REQUIRE(logged.has_value());
  CHECK(std::regex_search(*logged, std::regex(R"(from 127\.0\.0\.1:[0-9]+: no token)")));
  coord.Kill(SIGKILL);

  // Without a token on a non-loopback address: a warning at start-up; on loopback: none.
  Child open;
  REQUIRE(open.Start({Program(), "coordinator", job, "--out", out, "--domain", std::to_string(Domain(63)),
                      "--min-workers", "1", "--http", "0.0.0.0:0"},
                     &error));
  REQUIRE(open.WaitForLine("status: http://", 60s).has_value());
  CHECK(open.output().find("coordinator: warning: --http 0.0.0.0:0 serves the job's status") !=
        std::string::npos);
  CHECK(open.output().find("--http-token-file FILE") != std::string::npos);
  open.Kill(SIGKILL);
  Child local;
  REQUIRE(local.Start({Program(), "coordinator", job, "--out", out, "--domain", std::to_string(Domain(63)),
                       "--min-workers", "1"},
                      &error));
  REQUIRE(local.WaitForLine("status: http://", 60s).has_value());
  CHECK(local.output().find("warning") == std::string::npos);
  local.Kill(SIGKILL);
}

TEST_CASE("the dashboard with a token in headless Chromium: loads its data; a wrong token shows none",
          "[distributed][monitoring][http][integration]") {
  StatusModel model({"chromium-auth-job", 3, "shm", 2, 6, 10, 100, 20, 8, ""});
  HttpServerOptions opt;
  opt.bearer_token = kToken;
  auto server = HttpServer::Start(opt, StatusHandler(&model));
  REQUIRE(server.ok());
  const std::string url = (*server)->url();
  // The right token, pasted raw into the address ('+', '/', '=' as they are).
  {
    const std::string dom = DumpDom(url + "/?token=" + kToken);
    INFO(dom.substr(0, 4000));
    CHECK(ElementText(dom, "job") == "chromium-auth-job");  // the script's fetch got /status.json
    CHECK(ElementText(dom, "state") == "waiting");
    CHECK(ElementText(dom, "error").empty());
  }
  const uint64_t refused_before = (*server)->unauthorized();
  // A wrong token: the page itself is refused, so no data (this is what the check above would see
  // if the script did not send the token).
  {
    const std::string dom = DumpDom(url + "/?token=" + std::string(std::strlen(kToken), 'w'));
    INFO(dom.substr(0, 4000));
    CHECK(ElementText(dom, "job") != "chromium-auth-job");
    CHECK(dom.find("chromium-auth-job") == std::string::npos);
    CHECK(dom.find("401 Unauthorized") != std::string::npos);
  }
  CHECK((*server)->unauthorized() > refused_before);
  // The page served but its data refused (a handler answering 401 for /status.json): what the
  // first check would see if the script did not send the token: no data, the 401 reported.
  {
    const auto status_handler = StatusHandler(&model);
    auto refusing = HttpServer::Start(HttpServerOptions{}, [&](const HttpRequest& req) -> HttpResponse {
      if (req.path == "/status.json") return {401, "text/plain; charset=utf-8", kBody401};
      return status_handler(req);
    });
    REQUIRE(refusing.ok());
    const std::string dom = DumpDom((*refusing)->url() + "/?token=" + kToken);
    INFO(dom.substr(0, 4000));
    CHECK(ElementText(dom, "job") != "chromium-auth-job");
    CHECK(ElementText(dom, "error").find("HTTP 401") != std::string::npos);
  }
}

TEST_CASE("monitor refuses a server whose /status.json is not a coordinator's, at once",
          "[distributed][monitoring]") {
  // `{}` parses as an empty JobStatus: it used to print "tree 1/0 level 0/0" and, without --once,
  // poll forever.
  auto other = HttpServer::Start(HttpServerOptions{}, [](const HttpRequest&) -> HttpResponse {
    return {200, "application/json", "{}"};
  });
  REQUIRE(other.ok());
  const std::string bin = (poseforest::testing::BinDir() / "poseforest").string();
  for (const std::string once : {" --once", ""}) {
    auto r =
        poseforest::testing::RunCommand("timeout 60 " + bin + " monitor --url " + (*other)->url() + once);
    INFO(r.output);
    CHECK(r.exit_code == 1);
    CHECK(r.output.find("/status.json: not a poseforest coordinator's status") != std::string::npos);
  }
}
