#include "apps/live/live_page.h"

#include <httplib.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <mutex>
#include <thread>

namespace poseforest::apps::live {
namespace {

// The live page: a picture refreshed on every frame event, and the people of the frame.
constexpr const char* kPage = R"(<!doctype html>
<html><head><meta charset="utf-8"><title>poseforest live</title>
<style>body{background:#111;color:#ddd;font-family:sans-serif;margin:12px}
img{width:100%;max-width:1920px;image-rendering:pixelated}td{padding:0 8px}</style></head>
<body><h3>poseforest live: depth | parts | skeletons</h3>
<img id="view" alt="waiting for the first frame">
<p>frame <span id="frame">-</span>, <span id="count">0</span> people, <span id="fps">-</span> frames/s</p>
<table id="people"></table>
<script>
const es = new EventSource('/events' + location.search);  // ?frames=N: the stream ends after N
let last = 0, n = 0, t0 = performance.now();
es.onmessage = (e) => {
  const f = JSON.parse(e.data);
  document.getElementById('frame').textContent = f.index;
  document.getElementById('count').textContent = f.people.length;
  document.getElementById('view').src = '/frame.png?index=' + f.index;
  n++;
  const dt = (performance.now() - t0) / 1000;
  if (dt > 0) document.getElementById('fps').textContent = (n / dt).toFixed(1);
  const rows = f.people.map(p => {
    const tracked = p.joints.filter(j => j.tracked), inferred = p.joints.filter(j => j.state === 'inferred');
    return '<tr class="person" data-id="' + p.id + '"><td>id ' + p.id + '</td><td>' + tracked.length +
        ' joints tracked' + (inferred.length ? ', ' + inferred.length + ' inferred' : '') + '</td><td>' +
        tracked.map(j => j.name).join(' ') +
        (inferred.length ? ' (inferred: ' + inferred.map(j => j.name).join(' ') + ')' : '') + '</td></tr>';
  });
  document.getElementById('people').innerHTML = rows.join('');
};
</script></body></html>
)";

}  // namespace

// The latest frame for the page: its JSON record and its picture, and a sequence number the
// event streams wait on.
struct LivePage::Impl {
  std::mutex mu;
  std::condition_variable cv;
  uint64_t seq = 0;
  std::string json;
  std::vector<uint8_t> png;
  std::atomic<int> clients{0};
  bool closing = false;

  httplib::Server server;
  std::thread thread;

  void Routes();
};

void LivePage::Impl::Routes() {
  server.Get("/",
             [](const httplib::Request&, httplib::Response& res) { res.set_content(kPage, "text/html"); });
  server.Get("/skeletons.json", [this](const httplib::Request&, httplib::Response& res) {
    std::lock_guard lock(mu);
    res.set_content(json.empty() ? std::string("null") : json, "application/json");
  });
  server.Get("/frame.png", [this](const httplib::Request&, httplib::Response& res) {
    std::lock_guard lock(mu);
    if (png.empty()) {
      res.status = 404;
      return;
    }
    res.set_content(reinterpret_cast<const char*>(png.data()), png.size(), "image/png");
    res.set_header("Cache-Control", "no-store");
  });
  // Server-sent events: one "data:" line per frame, the frame's JSON Lines record.
  server.Get("/events", [this](const httplib::Request& req, httplib::Response& res) {
    res.set_header("Cache-Control", "no-store");
    auto last = std::make_shared<uint64_t>(0);
    // ?frames=N ends the stream after N frames (scripts, and the browser test: a page whose
    // stream has ended lets headless Chromium's virtual time run out and dump it).
    auto left = std::make_shared<long>(
        req.has_param("frames") ? std::atol(req.get_param_value("frames").c_str()) : -1);
    ++clients;
    res.set_chunked_content_provider(
        "text/event-stream",
        [this, last, left](size_t, httplib::DataSink& sink) {
          if (*left == 0) {
            sink.done();
            return true;
          }
          std::string msg;
          {
            std::unique_lock lock(mu);
            cv.wait_for(lock, std::chrono::seconds(1), [&] { return seq != *last || closing; });
            if (closing) return false;
            if (seq == *last) {
              msg = ": keep-alive\n\n";
            } else {
              *last = seq;
              // retry: a client whose stream ended (?frames=N) waits 10 minutes before asking again.
              msg = "retry: 600000\ndata: " + json + "\n\n";
              if (*left > 0) --*left;
            }
          }
          return sink.write(msg.data(), msg.size());
        },
        [this](bool) { --clients; });
  });
}

std::optional<Address> ParseAddress(const std::string& text) {
  Address a;
  std::string port_text = text;
  if (const auto colon = text.rfind(':'); colon != std::string::npos)
    a.host = text.substr(0, colon), port_text = text.substr(colon + 1);
  char* end = nullptr;
  const long port = std::strtol(port_text.c_str(), &end, 10);
  if (port_text.empty() || *end != '\0' || port < 0 || port > 65535) return std::nullopt;
  a.port = int(port);
  return a;
}

LivePage::LivePage() : impl_(std::make_unique<Impl>()) {}

LivePage::~LivePage() { Stop(); }

int LivePage::Start(const Address& address) {
  impl_->Routes();
  int bound = address.port;
  if (address.port == 0) {
    bound = impl_->server.bind_to_any_port(address.host.c_str());
  } else if (!impl_->server.bind_to_port(address.host.c_str(), address.port)) {
    bound = -1;
  }
  if (bound < 0) return -1;
  impl_->thread = std::thread([this] { impl_->server.listen_after_bind(); });
  return bound;
}

bool LivePage::running() const { return impl_->thread.joinable(); }

bool LivePage::page_open() const { return running() && impl_->clients.load() > 0; }

void LivePage::Publish(const std::string& json, std::optional<std::vector<uint8_t>> png) {
  {
    std::lock_guard lock(impl_->mu);
    if (png) impl_->png = std::move(*png);
    impl_->json = json;
    ++impl_->seq;
  }
  impl_->cv.notify_all();
}

void LivePage::Stop() {
  if (!impl_->thread.joinable()) return;
  {
    std::lock_guard lock(impl_->mu);
    impl_->closing = true;
  }
  impl_->cv.notify_all();
  impl_->server.stop();
  impl_->thread.join();
}

}  // namespace poseforest::apps::live
