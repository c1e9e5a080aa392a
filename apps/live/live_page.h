#pragma once
// `poseforest live --http`: the live page (depth | parts | skeletons at the camera's rate) on
// cpp-httplib, built when cpp-httplib is found at configure time (POSEFOREST_HAS_HTTPLIB). Endpoints:
// / (the page), /events (server-sent events: one JSON Lines record per frame; ?frames=N ends the
// stream after N), /skeletons.json (the latest record), /frame.png (the latest picture).
// cpp-httplib stays in live_page.cpp: its <resolv.h> `_res` macro breaks Eigen's headers.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace poseforest::apps::live {

/// Where --http listens: "HOST:PORT", or "PORT" for 127.0.0.1; port 0 = any free port.
struct Address {
  std::string host = "127.0.0.1";
  int port = 0;
};

/// The address of `text`, or nullopt when it is not HOST:PORT or PORT (0..65535).
std::optional<Address> ParseAddress(const std::string& text);

/// The page's server, on a thread of its own from Start to Stop (or destruction).
class LivePage {
 public:
  LivePage();
  ~LivePage();  ///< Stop()s a running server.
  LivePage(const LivePage&) = delete;
  LivePage& operator=(const LivePage&) = delete;

  /// Binds `address` and starts serving; the port bound (the one asked, or a free one for 0),
  /// or -1 when nothing can listen there.
  int Start(const Address& address);
  /// Whether the server runs (Start succeeded, Stop not yet called).
  bool running() const;
  /// Whether a page is open (an event stream connected): only then is a picture worth making.
  bool page_open() const;
  /// The frame's JSON Lines record, and its picture (PNG; nullopt: keep the previous one), to
  /// the endpoints and the connected event streams.
  void Publish(const std::string& json, std::optional<std::vector<uint8_t>> png);
  /// Ends the event streams and stops the server; idempotent.
  void Stop();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace poseforest::apps::live
