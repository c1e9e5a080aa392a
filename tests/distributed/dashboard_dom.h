#pragma once
// The web dashboard as a browser shows it: headless Chromium (Debian `chromium`, installed by
// scripts/setup.sh) loads a page, runs its script and dumps the DOM. For test_monitoring and
// test_http_auth.

#include <catch2/catch.hpp>
#include <filesystem>
#include <string>

#include "tests/distributed/dist_test_util.h"
#include "tests/support/process.h"

namespace poseforest::dist::testing {

/// The DOM of `url` (quoted for the shell) after its script has run for 4 s of virtual time.
inline std::string DumpDom(const std::string& url) {
  REQUIRE(std::filesystem::exists("/usr/bin/chromium"));  // scripts/setup.sh installs it
  TempDir profile("pf-chromium-profile");
  const std::string cmd =
      "timeout 90 /usr/bin/chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run "
      "--disable-background-networking --disable-component-update --disable-sync --disable-dev-shm-usage "
      "--user-data-dir=" +
      profile.path.string() + " --virtual-time-budget=4000 --dump-dom '" + url + "' 2>/dev/null";
  auto r = poseforest::testing::RunCommand(cmd);
  INFO(r.output.substr(0, 3000));
  REQUIRE(r.exit_code == 0);
  return r.output;
}

/// Text content of the element with `id` in a dumped DOM (flat elements only).
inline std::string ElementText(const std::string& dom, const std::string& id) {
  const size_t at = dom.find("id=\"" + id + "\"");
  if (at == std::string::npos) return "";
  const size_t open = dom.find('>', at);
  const size_t close = dom.find('<', open);
  return dom.substr(open + 1, close - open - 1);
}

}  // namespace poseforest::dist::testing
