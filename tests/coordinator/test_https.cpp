// HTTPS of the coordinator's status server (`--http-tls-cert`, `--http-tls-key`) and of its client
// (`monitor --url https://... --http-ca-file`), with a throwaway CA made by the `openssl` command in
// the test's folder: the same bytes as plain HTTP through our client and curl (TLS 1.2 and 1.3);
// plain HTTP, garbage and silent clients against the TLS port (no 200, counted, closed; the next
// TLS client served at once; the timeouts and the per-address cap still apply); clear client errors
// for an untrusted CA, a certificate for another host, https:// to a plain server; certificate and
// key files refused at start naming the file; real coordinator / `train --local-workers` / monitor
// processes with TLS and a token (/healthz open, the rest 401 without the token); the dashboard in
// headless Chromium over HTTPS. docs/distributed/monitoring.md#https.

#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <regex>
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
using poseforest::testing::RunCommand;
using poseforest::testing::RunPoseforest;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {
std::string Program() { return (HelperDir() / "poseforest").string(); }

std::string Body(const std::string& reply) {
  const size_t p = reply.find("\r\n\r\n");
  return p == std::string::npos ? "" : reply.substr(p + 4);
}

std::string Get(const std::string& target, const std::string& headers = "") {
  return "GET " + target + " HTTP/1.1\r\nHost: x\r\n" + headers + "\r\n";
}

/// `text` without its "now_unix" field (the one figure of a finished job's JSON that moves).
std::string WithoutNow(const std::string& text) {
  const std::string out = std::regex_replace(text, std::regex(R"("now_unix":[-0-9.e+]+,)"), "");
  CHECK(out.size() < text.size());
  return out;
}

std::string Quote(const fs::path& p) {
  std::string q = "'";
  q += p.string();
  q += '\'';
  return q;
}

/// A throwaway PKI in `dir`, made with the openssl command (keys 0600):
///   ca.pem / other-ca.pem      two CAs
///   server.pem + server.key    issued by ca for DNS:localhost, IP:127.0.0.1
///   elsewhere.pem + .key       issued by ca for DNS:coordinator.example only
///   chain.pem                  server.pem followed by ca.pem
///   expired.pem                server.key's certificate, valid in January 2020 only
///   weak.pem + weak.key        self-signed RSA-1024 (under OpenSSL's security level)
///   encrypted.key              server.key under a passphrase
struct Pki {
  fs::path dir;
  fs::path ca() const { return dir / "ca.pem"; }
  fs::path other_ca() const { return dir / "other-ca.pem"; }
  fs::path cert() const { return dir / "server.pem"; }
  fs::path key() const { return dir / "server.key"; }
};

Pki MakePki(const fs::path& dir) {
  const std::string script = R"(set -e
cd )" + Quote(dir) + R"(
key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1"; chmod 600 "$1"; }
key ca.key; openssl req -x509 -new -key ca.key -out ca.pem -days 2 -subj "/CN=poseforest test CA"
key other-ca.key; openssl req -x509 -new -key other-ca.key -out other-ca.pem -days 2 -subj "/CN=another CA"
issue() {  # NAME SUBJECT_ALT_NAMES
  key "$1.key"; openssl req -new -key "$1.key" -out "$1.csr" -subj "/CN=$1"
  printf 'subjectAltName=%s\n' "$2" > "$1.ext"
  openssl x509 -req -in "$1.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -out "$1.pem" -days 1 -extfile "$1.ext"
}
issue server "DNS:localhost,IP:127.0.0.1"
issue elsewhere "DNS:coordinator.example"
cat server.pem ca.pem > chain.pem
mkdir -p expired-ca; touch expired-ca/index.txt; echo 01 > expired-ca/serial
printf '[ca]\ndefault_ca=d\n[d]\ndatabase=expired-ca/index.txt\nnew_certs_dir=expired-ca\nserial=expired-ca/serial\npolicy=p\ndefault_md=sha256\n[p]\ncommonName=supplied\n' > expired-ca.cnf
openssl ca -batch -config expired-ca.cnf -cert ca.pem -keyfile ca.key -in server.csr -out expired.pem -startdate 20200101000000Z -enddate 20200102000000Z
openssl req -x509 -newkey rsa:1024 -nodes -keyout weak.key -out weak.pem -days 1 -subj "/CN=localhost"; chmod 600 weak.key
openssl pkey -in server.key -aes256 -passout pass:secret -out encrypted.key; chmod 600 encrypted.key
)";
  std::ofstream(dir / "make-pki.sh") << script;
  auto r = RunCommand("sh " + Quote(dir / "make-pki.sh"));
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
  return {dir};
}

/// The SHA-256 of the certificate's public key, base64 (Chromium's --ignore-certificate-errors-spki-list).
std::string SpkiHash(const fs::path& cert) {
  auto r = RunCommand(
      "openssl x509 -in " + Quote(cert) +
      " -pubkey -noout | openssl pkey -pubin -outform der | openssl dgst -sha256 -binary | base64");
  REQUIRE(r.exit_code == 0);
  std::string h = r.output;
  while (!h.empty() && (h.back() == '\n' || h.back() == '\r')) h.pop_back();
  REQUIRE(h.size() == 44);
  return h;
}

HttpServerOptions TlsOptions(const Pki& pki) {
  HttpServerOptions opt;
  opt.tls_cert_file = pki.cert().string();
  opt.tls_key_file = pki.key().string();
  return opt;
}

const char* const kToken = "https-test-token-0123456789";

fs::path WriteFile(const fs::path& p, const std::string& text, mode_t mode) {
  std::ofstream(p, std::ios::binary) << text;
  REQUIRE(::chmod(p.c_str(), mode) == 0);
  return p;
}

/// Polls `done` every 20 ms for up to `timeout`: a server counts a refused handshake when the
/// client's alert reaches it, which may be after the client has returned.
template <class F>
bool WaitUntil(F done, std::chrono::milliseconds timeout = 10s) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(20ms);
  }
  return true;
}

}  // namespace

TEST_CASE(
    "HTTPS: the status server over TLS serves the same bytes as plain HTTP (our client, curl, s_client)",
    "[distributed][monitoring][http][https][integration]") {
  TempDir dir("pf-https-bytes");
  const Pki pki = MakePki(dir.path);
  StatusModel model({"tls-job", 3, "shm", 2, 6, 10, 100, 20, 8, "/tmp/x.pff"});
  model.Finish(true, "wrote /tmp/x.pff");  // a final state: its JSON no longer changes
  auto tls = HttpServer::Start(TlsOptions(pki), StatusHandler(&model));
  REQUIRE(tls.ok());
  auto plain = HttpServer::Start(HttpServerOptions{}, StatusHandler(&model));
  REQUIRE(plain.ok());
  CHECK((*tls)->tls());
  CHECK_FALSE((*plain)->tls());
  const std::string port = std::to_string((*tls)->port());
  CHECK((*tls)->url() == "https://127.0.0.1:" + port);
  const std::string ca = pki.ca().string();

  // Our client, by name and by address (the certificate names both).
  for (const std::string& host : {std::string("localhost"), std::string("127.0.0.1")})
    for (const char* e : {"/", "/index.html", "/status.json", "/healthz"}) {
      INFO(host << e);
      auto secure = HttpGet("https://" + host + ":" + port + e, 5s, "", ca);
      INFO((secure.ok() ? "" : secure.status().message()));
      REQUIRE(secure.ok());
      auto clear = HttpGet((*plain)->url() + e, 5s);
      REQUIRE(clear.ok());
      if (std::string(e) == "/status.json")
        CHECK(WithoutNow(*secure) == WithoutNow(*clear));
      else
        CHECK(*secure == *clear);
    }
  auto json = HttpGet("https://localhost:" + port + "/status.json", 5s, "", ca);
  REQUIRE(json.ok());
  CHECK(json->find("\"job_id\":\"tls-job\"") != std::string::npos);
  auto metrics = HttpGet("https://localhost:" + port + "/metrics", 5s, "", ca);
  REQUIRE(metrics.ok());
  CHECK(metrics->find("poseforest_http_requests_total{outcome=\"tls_handshake_failed\"} 0\n") !=
        std::string::npos);
  CHECK(metrics->find("poseforest_job_state") != std::string::npos);

  // curl (another TLS client), TLS 1.2 and 1.3: the same bytes as our client over plain HTTP.
  REQUIRE(fs::exists("/usr/bin/curl"));  // scripts/setup.sh installs it
  for (const char* version : {"--tlsv1.2 --tls-max 1.2", "--tlsv1.3"})
    for (const char* e : {"/", "/status.json", "/healthz"}) {
      INFO(version << " " << e);
      const fs::path out = dir.path / "curl.out";
      auto r = RunCommand(std::string("curl -sS --fail --max-time 20 ") + version + " --cacert " +
                          Quote(pki.ca()) + " -o " + Quote(out) + " https://localhost:" + port + e);
      INFO(r.output);
      REQUIRE(r.exit_code == 0);
      auto clear = HttpGet((*plain)->url() + e, 5s);
      REQUIRE(clear.ok());
      if (std::string(e) == "/status.json")
        CHECK(WithoutNow(ReadText(out)) == WithoutNow(*clear));
      else
        CHECK(ReadText(out) == *clear);
    }
  // HEAD over TLS: the head only.
  {
    auto r = RunCommand("curl -sS --max-time 20 -I --cacert " + Quote(pki.ca()) +
                        " https://localhost:" + port + "/status.json");
    INFO(r.output);
    CHECK(r.exit_code == 0);
    CHECK(r.output.rfind("HTTP/1.1 200 OK\r\n", 0) == 0);
    CHECK(r.output.find("\"job_id\"") == std::string::npos);
  }
  // What openssl s_client negotiates: TLS 1.3 by default, 1.2 when asked; the chain verifies.
  for (const char* v : {"", "-tls1_2"}) {
    auto r = RunCommand("openssl s_client -brief -connect 127.0.0.1:" + port + " -CAfile " + Quote(pki.ca()) +
                        " " + v + " </dev/null");
    INFO(r.output);
    CHECK(r.output.find(std::string("Protocol version: ") + (*v ? "TLSv1.2" : "TLSv1.3")) !=
          std::string::npos);
    CHECK(r.output.find("Verification: OK") != std::string::npos);
  }

  // TLS 1.1 is refused for its version ("protocol version" alert, from our minimum of 1.2; without
  // it OpenSSL at Debian's security level would fail later with "internal error").
  {
    auto r = RunCommand("openssl s_client -brief -connect 127.0.0.1:" + port +
                        " -tls1_1 -cipher DEFAULT@SECLEVEL=0 " + "</dev/null");
    INFO(r.output);
    CHECK(r.exit_code != 0);
    CHECK(r.output.find("alert protocol version") != std::string::npos);
  }

  // Many clients at once: every one answered (the handshakes interleave on the one serving thread).
  const uint64_t before = (*tls)->requests();
  std::atomic<int> good{0};
  std::vector<std::thread> clients;
  for (int t = 0; t < 6; ++t)
    clients.emplace_back([&] {
      for (int i = 0; i < 5; ++i)
        good += HttpGet("https://localhost:" + port + "/status.json", 20s, "", ca).ok();
    });
  for (auto& t : clients) t.join();
  CHECK(good == 30);
  CHECK((*tls)->requests() - before == 30);
  CHECK((*tls)->tls_handshake_failures() == 1);  // the TLS 1.1 client

  // A certificate chain file (the server's certificate, then its CA) works the same.
  HttpServerOptions chained = TlsOptions(pki);
  chained.tls_cert_file = (dir.path / "chain.pem").string();
  auto chain = HttpServer::Start(chained, StatusHandler(&model));
  REQUIRE(chain.ok());
  auto via_chain = HttpGet("https://localhost:" + std::to_string((*chain)->port()) + "/healthz", 5s, "", ca);
  INFO((via_chain.ok() ? "" : via_chain.status().message()));
  CHECK(via_chain.ok());
}

TEST_CASE(
    "HTTPS: plain HTTP, garbage and silent clients neither hang nor stall the server; caps and timeouts hold",
    "[distributed][monitoring][http][https][integration]") {
  TempDir dir("pf-https-hostile");
  const Pki pki = MakePki(dir.path);
  StatusModel model({"hostile-tls-job", 3, "shm", 2, 6, 10, 100, 20, 8, ""});
  LogLines log_lines;
  HttpServerOptions opt = TlsOptions(pki);
  opt.timeout = 5s;
  opt.max_connections_per_peer = 4;
  opt.log = log_lines.Sink();
  auto server = HttpServer::Start(opt, StatusHandler(&model));
  REQUIRE(server.ok());
  const uint16_t port = (*server)->port();
  const std::string url = "https://localhost:" + std::to_string(port);
  const std::string ca = pki.ca().string();

  // Plain HTTP to the TLS port: a plain 400 that says to use https://, at once (not at the timeout):
  // the client gives up after 4 s, before the server's 5 s, so a close seen by the client is the
  // server's answer, not its timeout.
  const Exchange plain_exchange = RawExchangeUntilClosed(port, Get("/status.json"), 4s);
  const std::string& plain = plain_exchange.bytes;
  INFO(plain);
  CHECK(plain_exchange.closed_by_peer);
  CHECK(StatusCode(plain) == 400);
  CHECK(Body(plain) == "400 Bad Request: this port speaks HTTPS only: use https:// instead of http://\n");
  CHECK(plain.find("hostile-tls-job") == std::string::npos);
  CHECK((*server)->tls_handshake_failures() == 1);
  // Our client over http:// to it: the server's words, InvalidArgument (retrying will not help).
  auto http_client = HttpGet("http://127.0.0.1:" + std::to_string(port) + "/status.json", 5s);
  REQUIRE(!http_client.ok());
  CHECK(http_client.status().code() == core::ErrorCode::kInvalidArgument);
  CHECK(http_client.status().message().find("HTTP 400: 400 Bad Request: this port speaks HTTPS only") !=
        std::string::npos);
  // Garbage (a TLS record header and junk): closed at once, counted; no HTTP spoken.
  const Exchange junk = RawExchangeUntilClosed(port, std::string("\x16\x03\x01\x00\x05hello, world", 17), 4s);
  CHECK(junk.closed_by_peer);
  CHECK(junk.bytes.find("HTTP/1.1") == std::string::npos);
  CHECK((*server)->tls_handshake_failures() == 3);
  // Connected and closed without a byte (a TCP port check): not a failure.
  ::close(ConnectLoopback(port));
  std::this_thread::sleep_for(200ms);
  CHECK((*server)->tls_handshake_failures() == 3);
  auto after = HttpGet(url + "/status.json", 5s, "", ca);
  INFO((after.ok() ? "" : after.status().message()));
  REQUIRE(after.ok());  // the next TLS client is served
  CHECK(after->find("hostile-tls-job") != std::string::npos);

  // Silent clients from 127.0.0.2: three that never send a ClientHello and one that stops in the
  // middle of it. A TLS client from 127.0.0.1 is served at once meanwhile: a handshake that waited
  // for them would take the server's 5 s timeout at least, and each client gives up after 4 s.
  std::vector<int> silent;
  for (int i = 0; i < 3; ++i) silent.push_back(ConnectLoopback(port, "127.0.0.2"));
  silent.push_back(ConnectLoopback(port, "127.0.0.2"));
  REQUIRE(::send(silent.back(), "\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03", 11, MSG_NOSIGNAL) == 11);
  std::this_thread::sleep_for(200ms);
  for (int i = 0; i < 3; ++i) {
    auto r = HttpGet(url + "/healthz", 4s, "", ca);
    INFO((r.ok() ? "" : r.status().message()));
    CHECK(r.ok());
  }
  // The per-address cap holds under TLS: a fifth connection from 127.0.0.2 is closed at once
  // (no 503 text: there is no TLS session to say it in).
  const Exchange fifth = RawExchangeUntilClosed(port, "", 4s, "127.0.0.2");
  CHECK(fifth.closed_by_peer);  // closed by the server, not left to the client's 4 s
  CHECK(fifth.bytes.empty());
  CHECK((*server)->dropped() == 1);
  // The timeout holds: the silent ones are closed by the server (EOF), counted as bad requests.
  const uint64_t bad_before = (*server)->bad_requests();
  for (int fd : silent) {
    pollfd p{fd, POLLIN, 0};
    CHECK(::poll(&p, 1, 10000) == 1);
    char buf[64];
    CHECK(::recv(fd, buf, sizeof buf, 0) <= 0);
    ::close(fd);
  }
  std::this_thread::sleep_for(100ms);
  CHECK((*server)->bad_requests() - bad_before == 4);
  CHECK((*server)->tls_handshake_failures() == 3);
  auto last = HttpGet(url + "/healthz", 5s, "", ca);
  CHECK(last.ok());
  const std::string all = log_lines.Joined();
  INFO(all);
  CHECK(std::regex_search(
      all, std::regex(
               R"(http: TLS handshake with 127\.0\.0\.1:[0-9]+ failed: plain HTTP sent to the HTTPS port)")));
  CHECK(std::regex_search(
      all, std::regex(R"(http: 503 for a connection from 127\.0\.0\.2:[0-9]+: 4 already open)")));
}

TEST_CASE("HTTPS client: untrusted CA, a certificate for another host, https:// to plain HTTP: clear errors",
          "[distributed][monitoring][http][https][integration]") {
  TempDir dir("pf-https-client");
  const Pki pki = MakePki(dir.path);
  StatusModel model({"client-tls-job", 3, "shm", 2, 6, 10, 100, 20, 8, ""});
  auto server = HttpServer::Start(TlsOptions(pki), StatusHandler(&model));
  REQUIRE(server.ok());
  const std::string url = "https://localhost:" + std::to_string((*server)->port()) + "/status.json";
  auto error = [](const core::Result<std::string>& r) {
    REQUIRE(!r.ok());
    INFO(r.status().message());
    CHECK(r.status().code() == core::ErrorCode::kInvalidArgument);  // monitor stops at once
    return r.status().message();
  };
  // The system's trust store does not know our CA; another CA does not sign it.
  const std::string untrusted = error(HttpGet(url, 5s));
  CHECK(untrusted.find(
            url + ": the server's certificate is not trusted (unable to get local issuer certificate)") == 0);
  CHECK(untrusted.find("give the CA that signed it with --http-ca-file FILE") != std::string::npos);
  const std::string other = error(HttpGet(url, 5s, "", pki.other_ca().string()));
  CHECK(other.find("not trusted") != std::string::npos);
  CHECK(other.find("it does not chain to a CA in --http-ca-file " + pki.other_ca().string()) !=
        std::string::npos);
  // The right CA, but the certificate names another host.
  HttpServerOptions elsewhere;
  elsewhere.tls_cert_file = (dir.path / "elsewhere.pem").string();
  elsewhere.tls_key_file = (dir.path / "elsewhere.key").string();
  auto misnamed = HttpServer::Start(elsewhere, StatusHandler(&model));
  REQUIRE(misnamed.ok());
  const std::string port2 = std::to_string((*misnamed)->port());
  CHECK(error(HttpGet("https://localhost:" + port2 + "/healthz", 5s, "", pki.ca().string()))
            .find("the server's certificate is not for localhost (hostname mismatch)") != std::string::npos);
  CHECK(error(HttpGet("https://127.0.0.1:" + port2 + "/healthz", 5s, "", pki.ca().string()))
            .find("the server's certificate is not for 127.0.0.1 (IP address mismatch)") !=
        std::string::npos);
  // https:// to a plain server: refused at once (its ClientHello gets a plain 400), not at the
  // server's 5 s timeout: the client gives up after 4 s, and a timeout would read differently.
  auto plain = HttpServer::Start(HttpServerOptions{}, StatusHandler(&model));
  REQUIRE(plain.ok());
  CHECK(error(HttpGet("https://127.0.0.1:" + std::to_string((*plain)->port()) + "/healthz", 4s, "",
                      pki.ca().string()))
            .find("the server does not speak TLS: is it http://?") != std::string::npos);
  CHECK((*plain)->bad_requests() == 1);
  const std::string hello = RawExchange((*plain)->port(), std::string("\x16\x03\x01\x00\x05hello", 10));
  CHECK(StatusCode(hello) == 400);
  CHECK(Body(hello) == "400 Bad Request: this port speaks plain HTTP, not TLS: use http://\n");
  // CA files: missing, not PEM, for http://.
  CHECK(error(HttpGet(url, 5s, "", (dir.path / "missing.pem").string()))
            .find("--http-ca-file " + (dir.path / "missing.pem").string() + ": No such file") == 0);
  CHECK(error(HttpGet(url, 5s, "", (dir.path / "server.csr").string())).find("no PEM certificate in it") !=
        std::string::npos);
  CHECK(error(HttpGet("http://127.0.0.1:" + std::to_string((*plain)->port()) + "/healthz", 5s, "",
                      pki.ca().string()))
            .find("--http-ca-file is for https:// URLs") != std::string::npos);
  CHECK(CheckHttpCaFile(pki.ca().string()).ok());
  // Bad URLs.
  CHECK(error(HttpGet("ftp://127.0.0.1/x", 1s)).find("expected http://HOST[:PORT][/PATH] or https://") !=
        std::string::npos);
  CHECK(error(HttpGet("https://127.0.0.1:99999/x", 1s)).find("port must be 1..65535") != std::string::npos);
  CHECK(error(HttpGet("https://bad_host!/x", 1s)).find("a host name") != std::string::npos);
  // The refused handshakes were counted by the servers (the client aborts with an alert).
  CHECK(WaitUntil([&] {
    return (*server)->tls_handshake_failures() >= 2 && (*misnamed)->tls_handshake_failures() >= 2;
  }));
  CHECK((*server)->tls_handshake_failures() == 2);
  CHECK((*misnamed)->tls_handshake_failures() == 2);
  // And the right CA and name work.
  auto good = HttpGet(url, 5s, "", pki.ca().string());
  INFO((good.ok() ? "" : good.status().message()));
  CHECK(good.ok());
}

TEST_CASE("HTTPS server: bad certificate or key files are refused at start, naming the file",
          "[distributed][monitoring][http][https][integration]") {
  TempDir dir("pf-https-files");
  const Pki pki = MakePki(dir.path);
  const fs::path garbage = WriteFile(dir.path / "garbage.pem", "not a certificate\n", 0600);
  const fs::path loose = dir.path / "loose.key";
  fs::copy_file(pki.key(), loose);
  REQUIRE(::chmod(loose.c_str(), 0644) == 0);
  const fs::path cert_as_key = dir.path / "cert-as-key.pem";
  fs::copy_file(pki.cert(), cert_as_key);
  REQUIRE(::chmod(cert_as_key.c_str(), 0600) == 0);
  struct Bad {
    fs::path cert, key;
    std::string starts, contains;
  };
  const std::string c = "--http-tls-cert ", k = "--http-tls-key ";
  const std::vector<Bad> bad = {
      {dir.path / "missing.pem", pki.key(), c + (dir.path / "missing.pem").string() + ": ", "No such file"},
      {pki.cert(), dir.path / "missing.key", k + (dir.path / "missing.key").string() + ": ", "No such file"},
      {dir.path, pki.key(), c + dir.path.string() + ": ", "not a regular file"},
      {garbage, pki.key(), c + garbage.string() + ": ", "no PEM certificate in it"},
      {pki.cert(), garbage, k + garbage.string() + ": ", "no PEM private key in it"},
      {pki.cert(), cert_as_key, k + cert_as_key.string() + ": ", "no PEM private key in it"},
      {pki.cert(), dir.path / "elsewhere.key", k + (dir.path / "elsewhere.key").string() + ": ",
       "does not match the certificate in --http-tls-cert " + pki.cert().string()},
      {pki.cert(), loose, k + loose.string() + ": ", "permissions 0644 are too open"},
      {pki.cert(), dir.path / "encrypted.key", k + (dir.path / "encrypted.key").string() + ": ",
       "encrypted with a passphrase"},
      {dir.path / "expired.pem", pki.key(), c + (dir.path / "expired.pem").string() + ": ",
       "expired on Jan  2 00:00:00 2020 GMT"},
      {dir.path / "weak.pem", dir.path / "weak.key", c + (dir.path / "weak.pem").string() + ": ",
       "refused by OpenSSL: ee key too small"},
      {pki.cert(), "", "--http-tls-cert and --http-tls-key go together", "only --http-tls-cert was given"},
      {"", pki.key(), "--http-tls-cert and --http-tls-key go together", "only --http-tls-key was given"},
  };
  StatusModel model({"files-job", 3, "shm", 2, 6, 10, 100, 20, 8, ""});
  for (const Bad& b : bad) {
    INFO(b.cert << " / " << b.key);
    const core::Status st = CheckHttpTlsFiles(b.cert.string(), b.key.string());
    REQUIRE(!st.ok());
    INFO(st.message());
    CHECK(st.code() == core::ErrorCode::kInvalidArgument);
    CHECK(st.message().rfind(b.starts, 0) == 0);
    CHECK(st.message().find(b.contains) != std::string::npos);
    HttpServerOptions opt;
    opt.tls_cert_file = b.cert.string();
    opt.tls_key_file = b.key.string();
    auto server = HttpServer::Start(opt, StatusHandler(&model));
    REQUIRE(!server.ok());
    CHECK(server.status().message() == st.message());
  }
  CHECK(CheckHttpTlsFiles(pki.cert().string(), pki.key().string()).ok());
  // A root-owned key readable by its group is fine (a Kubernetes Secret with fsGroup: 0440).
  if (::geteuid() == 0) {
    const fs::path group = dir.path / "group.key";
    fs::copy_file(pki.key(), group);
    REQUIRE(::chmod(group.c_str(), 0440) == 0);
    const core::Status st = CheckHttpTlsFiles(pki.cert().string(), group.string());
    INFO(st.message());
    CHECK(st.ok());
  }
}

TEST_CASE("coordinator, train --local-workers and monitor over HTTPS with a token: real processes",
          "[distributed][monitoring][http][https][integration]") {
  TempDir dir("pf-https-run");
  const Pki pki = MakePki(dir.path);
  std::ofstream(dir.path / "job.textproto") << TinyJobText(1, 4);
  const std::string job = (dir.path / "job.textproto").string();
  const std::string out = (dir.path / "forest.pff").string();
  const fs::path token_file = WriteFile(dir.path / "token", std::string(kToken) + "\n", 0600);
  const std::string cert = pki.cert().string(), key = pki.key().string(), ca = pki.ca().string();
  const std::string tls_flags = " --http-tls-cert " + cert + " --http-tls-key " + key;

  // Bad TLS flags: exit 2 naming the file or flag, with and without --check-config, and through
  // `train --local-workers` (the same flags); the job file is the same.
  const std::string elsewhere_key = (dir.path / "elsewhere.key").string();
  for (const std::string& prefix :
       {"coordinator " + job + " --out " + out, "coordinator " + job + " --out " + out + " --check-config",
        "train " + job + " --out " + out + " --local-workers 1"}) {
    const std::pair<std::string, std::string> cases[] = {
        {" --http-tls-cert " + cert, "--http-tls-cert and --http-tls-key go together"},
        {" --http-tls-cert " + cert + " --http-tls-key " + elsewhere_key,
         "--http-tls-key " + elsewhere_key + ": does not match the certificate"},
        {" --http-tls-cert " + (dir.path / "nope.pem").string() + " --http-tls-key " + key,
         "--http-tls-cert " + (dir.path / "nope.pem").string() + ": No such file"},
    };
    for (const auto& [flags, expect] : cases) {
      auto r = RunPoseforest(prefix + flags);
      INFO(prefix << flags << ": " << r.output);
      CHECK(r.exit_code == 2);
      CHECK(r.output.find(expect) != std::string::npos);
    }
  }
  {
    auto r = RunPoseforest("coordinator " + job + " --out " + out + " --http off" + tls_flags);
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK(r.output.find("not --http off") != std::string::npos);
    auto ok = RunPoseforest("coordinator " + job + " --out " + out + " --check-config" + tls_flags);
    INFO(ok.output);
    CHECK(ok.exit_code == 0);
  }

  // A coordinator with TLS and a token (it waits for a worker that never comes).
  Child coord;
  std::string error;
  REQUIRE(coord.Start({Program(), "coordinator", job, "--out", out, "--domain", std::to_string(Domain(71)),
                       "--min-workers", "1", "--worker-wait-s", "120", "--http-token-file",
                       token_file.string(), "--http-tls-cert", cert, "--http-tls-key", key},
                      &error));
  auto line = coord.WaitForLine("status: https://", 60s);
  INFO(coord.output());
  REQUIRE(line.has_value());
  const std::string printed =
      line->substr(line->find("https://"), line->find("/ (dashboard)") - line->find("https://"));
  const std::string port = printed.substr(printed.rfind(':') + 1);
  const std::string url = "https://localhost:" + port;  // the name the certificate has
  CHECK(coord.WaitForLine("status: HTTPS only (certificate " + cert + ")", 10s).has_value());
  CHECK(coord.output().find(kToken) == std::string::npos);
  // /healthz without the token; the rest want it.
  auto healthz = HttpGet(url + "/healthz", 5s, "", ca);
  INFO((healthz.ok() ? "" : healthz.status().message()));
  CHECK(healthz.ok());
  CHECK((healthz.ok() && *healthz == "ok\n"));
  for (const char* e : {"/", "/status.json", "/metrics"}) {
    INFO(e);
    auto none = HttpGet(url + e, 5s, "", ca);
    REQUIRE(!none.ok());
    CHECK(none.status().message().find("HTTP 401") != std::string::npos);
    auto with = HttpGet(url + e, 5s, kToken, ca);
    INFO((with.ok() ? "" : with.status().message()));
    CHECK(with.ok());
  }
  {
    auto r = RunCommand("curl -sS --max-time 20 --cacert " + Quote(pki.ca()) +
                        " -o /dev/null -o /dev/null -w '%{http_code}' " + url + "/healthz " + url +
                        "/status.json");
    INFO(r.output);
    CHECK(r.exit_code == 0);
    CHECK(r.output == "200401");
  }
  auto mon = RunPoseforest("monitor --once --url " + url + " --http-ca-file " + ca + " --http-token-file " +
                           token_file.string());
  INFO(mon.output);
  CHECK(mon.exit_code == 0);
  CHECK(mon.output.find("state waiting") != std::string::npos);
  // Without the CA: exit 1 at once, saying what to do; a monitor that kept retrying until
  // --timeout-s would end with "(for 60 s; last state: ...)" instead.
  auto untrusted =
      RunPoseforest("monitor --url " + url + " --timeout-s 60 --http-token-file " + token_file.string());
  INFO(untrusted.output);
  CHECK(untrusted.exit_code == 1);
  CHECK(untrusted.output.find("(for 60 s") == std::string::npos);
  CHECK(untrusted.output.find("not trusted") != std::string::npos);
  CHECK(untrusted.output.find("--http-ca-file") != std::string::npos);
  auto missing_ca =
      RunPoseforest("monitor --once --url " + url + " --http-ca-file " + (dir.path / "no.pem").string());
  INFO(missing_ca.output);
  CHECK(missing_ca.exit_code == 2);
  CHECK(missing_ca.output.find("--http-ca-file " + (dir.path / "no.pem").string() + ": No such file") !=
        std::string::npos);
  auto ca_for_http = RunPoseforest("monitor --once --url http://127.0.0.1:" + port + " --http-ca-file " + ca);
  INFO(ca_for_http.output);
  CHECK(ca_for_http.exit_code == 2);
  CHECK(ca_for_http.output.find("--http-ca-file is for https:// URLs") != std::string::npos);
  auto logged = coord.WaitForLine("http: TLS handshake with 127.0.0.1:", 10s);
  CHECK(logged.has_value());
  coord.Kill(SIGKILL);

  // On every interface: a token without TLS is warned about; with TLS it is not.
  Child clear;
  REQUIRE(clear.Start({Program(), "coordinator", job, "--out", out, "--domain", std::to_string(Domain(73)),
                       "--min-workers", "1", "--http", "0.0.0.0:0", "--http-token-file", token_file.string()},
                      &error));
  REQUIRE(clear.WaitForLine("status: http://", 60s).has_value());
  CHECK(clear.output().find(
            "coordinator: warning: --http 0.0.0.0:0 with --http-token-file but without "
            "--http-tls-cert/--http-tls-key: the token and the job's status cross the network in "
            "clear text") != std::string::npos);
  clear.Kill(SIGKILL);
  Child secure;
  REQUIRE(secure.Start({Program(), "coordinator", job, "--out", out, "--domain", std::to_string(Domain(73)),
                        "--min-workers", "1", "--http", "0.0.0.0:0", "--http-token-file", token_file.string(),
                        "--http-tls-cert", cert, "--http-tls-key", key},
                       &error));
  REQUIRE(secure.WaitForLine("status: https://", 60s).has_value());
  CHECK(secure.output().find("warning") == std::string::npos);
  secure.Kill(SIGKILL);

  // `train --local-workers 1` with TLS and a token runs the job to the end; the monitor follows it
  // over HTTPS until "done".
  Child train;
  REQUIRE(train.Start(
      {Program(), "train", job, "--out", out, "--local-workers", "1", "--domain", std::to_string(Domain(75)),
       "--http-token-file", token_file.string(), "--http-tls-cert", cert, "--http-tls-key", key},
      &error));
  auto train_line = train.WaitForLine("status: https://", 60s);
  INFO(train.output());
  REQUIRE(train_line.has_value());
  const std::string train_url = train_line->substr(
      train_line->find("https://"), train_line->find("/ (dashboard)") - train_line->find("https://"));
  auto follow = RunPoseforest("monitor --url " + train_url + " --http-ca-file " + ca + " --http-token-file " +
                              token_file.string() + " --timeout-s 60 --interval-ms 200");
  INFO(follow.output);
  CHECK(follow.exit_code == 0);
  CHECK(follow.output.find("state done") != std::string::npos);
  auto train_exit = train.Wait(120s);
  INFO(train.output());
  REQUIRE(train_exit.has_value());
  CHECK(*train_exit == 0);
  CHECK(fs::file_size(out) > 0);
}

TEST_CASE("the dashboard over HTTPS in headless Chromium: loads its data with the token",
          "[distributed][monitoring][http][https][integration]") {
  TempDir dir("pf-https-chromium");
  const Pki pki = MakePki(dir.path);
  StatusModel model({"chromium-tls-job", 3, "shm", 2, 6, 10, 100, 20, 8, ""});
  HttpServerOptions opt = TlsOptions(pki);
  opt.bearer_token = kToken;
  auto server = HttpServer::Start(opt, StatusHandler(&model));
  REQUIRE(server.ok());
  const std::string url = "https://localhost:" + std::to_string((*server)->port());
  // Chromium trusts this server's key only (its SPKI hash), not every certificate.
  const std::string trust = "--ignore-certificate-errors-spki-list=" + SpkiHash(pki.cert());
  {
    const std::string dom = DumpDom(url + "/?token=" + kToken, trust);
    INFO(dom.substr(0, 4000));
    CHECK(ElementText(dom, "job") == "chromium-tls-job");  // the script's fetch of status.json over TLS
    CHECK(ElementText(dom, "state") == "waiting");
    CHECK(ElementText(dom, "error").empty());
  }
  const uint64_t failures = (*server)->tls_handshake_failures();
  // Without that trust, Chromium refuses the certificate: no page, no data.
  {
    const std::string dom = DumpDom(url + "/?token=" + kToken);
    INFO(dom.substr(0, 4000));
    CHECK(dom.find("chromium-tls-job") == std::string::npos);
  }
  CHECK(WaitUntil([&] { return (*server)->tls_handshake_failures() > failures; }));
}

TEST_CASE("HTTPS: clients that go away in the middle of a large reply do not kill the process (SIGPIPE)",
          "[distributed][monitoring][http][https][integration]") {
  TempDir dir("pf-https-sigpipe");
  const Pki pki = MakePki(dir.path);
  // A 16 MiB reply: many TLS records, many write()s, the later ones after the client has gone.
  const std::string big(16u << 20, 'x');
  auto server = HttpServer::Start(TlsOptions(pki), [&](const HttpRequest& req) -> HttpResponse {
    if (req.path == "/big") {
      std::this_thread::sleep_for(300ms);  // long enough for the client to close first
      return {200, "text/plain", big};
    }
    return {200, "text/plain", "ok\n"};
  });
  REQUIRE(server.ok());
  const std::string port = std::to_string((*server)->port());
  // A client (Python's ssl, TLS 1.2: no session tickets left unread after the handshake) sends the
  // request and closes at once: the server then writes into a connection in CLOSE_WAIT, the
  // client's kernel resets it, and the server's next write() fails with EPIPE.
  const fs::path script = dir.path / "go-away.py";
  std::ofstream(script)
      << "import socket, ssl, sys\n"
         "ctx = ssl.create_default_context(cafile=sys.argv[1])\n"
         "ctx.maximum_version = ssl.TLSVersion.TLSv1_2\n"
         "for i in range(3):\n"
         "    s = ctx.wrap_socket(socket.create_connection(('127.0.0.1', int(sys.argv[2]))),\n"
         "                        server_hostname='localhost')\n"
         "    s.sendall(b'GET /big HTTP/1.1\\r\\nHost: x\\r\\n\\r\\n')\n"
         "    s.close()\n"
         "print('sent')\n";
  auto go_away = RunCommand("python3 " + Quote(script) + " " + Quote(pki.ca()) + " " + port);
  INFO(go_away.output);
  REQUIRE(go_away.exit_code == 0);
  std::this_thread::sleep_for(500ms);
  // Still here (a SIGPIPE would have ended this test program), and serving.
  auto r = HttpGet("https://localhost:" + port + "/small", 10s, "", pki.ca().string());
  INFO((r.ok() ? "" : r.status().message()));
  CHECK(r.ok());
  auto whole = HttpGet("https://localhost:" + port + "/big", 30s, "", pki.ca().string());
  REQUIRE(whole.ok());
  CHECK(whole->size() == big.size());
}
