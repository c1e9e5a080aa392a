#include "proto/http/prometheus_text.h"

#include <time.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <sstream>

#include "proto/http/http_server.h"

namespace poseforest::proto::http {

std::string PromLabelValue(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    if (c == '\\')
      out += "\\\\";
    else if (c == '"')
      out += "\\\"";
    else if (c == '\n')
      out += "\\n";
    else
      out += c;
  }
  return out;
}

std::string PromNumber(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "+Inf" : "-Inf";
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

void AppendPromFamily(std::string* out, std::string_view name, std::string_view type, std::string_view help,
                      const std::vector<std::pair<std::string, double>>& samples) {
  std::string& m = *out;
  m.append("# HELP ").append(name).append(" ");
  for (char c : help) {  // HELP escapes backslash and newline only
    if (c == '\\')
      m += "\\\\";
    else if (c == '\n')
      m += "\\n";
    else
      m += c;
  }
  m.append("\n# TYPE ").append(name).append(" ").append(type).append("\n");
  for (const auto& [labels, v] : samples) {
    m.append(name);
    if (!labels.empty()) m.append("{").append(labels).append("}");
    m.append(" ").append(PromNumber(v)).append("\n");
  }
}

std::string HttpServerMetrics(const HttpServer& server) {
  std::string out =
      "# HELP poseforest_http_requests_total Requests and connections of the status server, by outcome "
      "(ok: answered; bad_request: 400/405/408/431; unauthorized: 401, no or a wrong token; "
      "rejected_connection: 503, over the connection limits; tls_handshake_failed: HTTPS only, a failed TLS "
      "handshake, plain HTTP to the port included).\n"
      "# TYPE poseforest_http_requests_total counter\n";
  const std::pair<const char*, uint64_t> rows[] = {{"ok", server.requests()},
                                                   {"bad_request", server.bad_requests()},
                                                   {"unauthorized", server.unauthorized()},
                                                   {"rejected_connection", server.dropped()},
                                                   {"tls_handshake_failed", server.tls_handshake_failures()}};
  for (const auto& [outcome, n] : rows)
    out += std::string("poseforest_http_requests_total{outcome=\"") + outcome + "\"} " + std::to_string(n) +
           "\n";
  return out;
}

namespace {
std::string ReadProcFile(const char* path) {
  std::ifstream in(path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// The process's start as Unix seconds (/proc/self/stat field 22, clock ticks after boot, plus
/// btime of /proc/stat); < 0 when unknown.
double ProcessStartUnix() {
  const std::string stat = ReadProcFile("/proc/self/stat");
  const size_t paren = stat.rfind(')');  // the command name may hold spaces and parentheses
  if (paren == std::string::npos) return -1;
  std::istringstream fields(stat.substr(paren + 1));
  std::string f;
  // After the name: field 3 (state) ... field 22 (starttime): 20 fields.
  for (int i = 3; i <= 22; ++i)
    if (!(fields >> f)) return -1;
  const double ticks = std::strtod(f.c_str(), nullptr);
  std::istringstream lines(ReadProcFile("/proc/stat"));
  for (std::string line; std::getline(lines, line);)
    if (line.rfind("btime ", 0) == 0) {
      const long hz = ::sysconf(_SC_CLK_TCK);
      return hz > 0 ? std::strtod(line.c_str() + 6, nullptr) + ticks / double(hz) : -1;
    }
  return -1;
}
}  // namespace

std::string ProcessMetrics() {
  std::string out;
  timespec ts{};
  ::clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  AppendPromFamily(&out, "process_cpu_seconds_total", "counter",
                   "Total user and system CPU time spent in seconds (every thread of the process).",
                   {{"", double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec)}});
  // /proc/self/statm: size, resident (pages).
  std::istringstream statm(ReadProcFile("/proc/self/statm"));
  uint64_t size_pages = 0, resident_pages = 0;
  if (statm >> size_pages >> resident_pages)
    AppendPromFamily(&out, "process_resident_memory_bytes", "gauge", "Resident memory size in bytes.",
                     {{"", double(resident_pages) * double(::sysconf(_SC_PAGESIZE))}});
  if (const double start = ProcessStartUnix(); start > 0)
    AppendPromFamily(&out, "process_start_time_seconds", "gauge",
                     "Start time of the process since unix epoch in seconds.", {{"", start}});
  return out;
}

}  // namespace poseforest::proto::http
