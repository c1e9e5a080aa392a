#include "coordinator/monitoring/dashboard.h"

#include "proto/http/prometheus_text.h"

namespace poseforest::coordinator::monitoring {

namespace {
// Everything inline: the page works from a machine with no other network access. The script
// only ever writes textContent / SVG attributes, never HTML, so worker ids and messages from
// the network cannot inject markup.
const char* const kDashboard = R"HTML(<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>poseforest training</title>
<style>
 body { font: 14px/1.4 system-ui, sans-serif; margin: 16px 24px; color: #222; background: #fafafa; }
 h1 { font-size: 20px; margin: 0 0 4px 0; }
 h2 { font-size: 15px; margin: 18px 0 6px 0; }
 .muted { color: #777; }
 .cards { display: flex; flex-wrap: wrap; gap: 10px; margin: 10px 0; }
 .card { background: #fff; border: 1px solid #ddd; border-radius: 6px; padding: 6px 12px; min-width: 110px; }
 .card .k { font-size: 11px; color: #777; text-transform: uppercase; }
 .card .v { font-size: 18px; font-weight: 600; }
 #bar { height: 18px; background: #e4e4e4; border-radius: 9px; overflow: hidden; max-width: 900px; }
 #bar-fill { height: 100%; width: 0%; background: #2f7ed8; transition: width 0.5s; }
 table { border-collapse: collapse; background: #fff; font-size: 13px; }
 th, td { border: 1px solid #ddd; padding: 2px 8px; text-align: right; }
 th { background: #f0f0f0; }
 td.l, th.l { text-align: left; }
 .state-training { color: #1a7f37; } .state-lost, .state-evicted, .state-failed { color: #c62828; }
 .state-done { color: #2f7ed8; } .state-joined, .state-waiting { color: #b26a00; }
 #levels-wrap { max-height: 320px; overflow-y: auto; display: inline-block; }
 #error { color: #c62828; }
</style>
</head>
<body>
<h1>poseforest training &mdash; <span id="job">loading&hellip;</span></h1>
<div class="muted">state <b id="state">?</b> &middot; <span id="message"></span> <span id="error"></span></div>
<div class="cards">
 <div class="card"><div class="k">tree</div><div class="v" id="tree">&ndash;</div></div>
 <div class="card"><div class="k">level</div><div class="v" id="level">&ndash;</div></div>
 <div class="card"><div class="k">nodes done / total</div><div class="v" id="nodes">&ndash;</div></div>
 <div class="card"><div class="k">samples/s</div><div class="v" id="sps">&ndash;</div></div>
 <div class="card"><div class="k">evaluations/s</div><div class="v" id="eps">&ndash;</div></div>
 <div class="card"><div class="k">ETA</div><div class="v" id="eta">&ndash;</div></div>
 <div class="card"><div class="k">elapsed</div><div class="v" id="elapsed">&ndash;</div></div>
 <div class="card"><div class="k">workers alive</div><div class="v" id="alive">&ndash;</div></div>
</div>
<div id="bar"><div id="bar-fill"></div></div>
<div class="muted" id="progress-text">progress &ndash;</div>

<h2>Workers</h2>
<table id="workers-table">
 <thead><tr><th class="l">worker</th><th class="l">state</th><th>frames</th><th>replies</th>
 <th>evaluations/s (10 s)</th><th>evaluations</th><th>received</th><th>last seen</th></tr></thead>
 <tbody id="workers"></tbody>
</table>

<h2>Throughput per level</h2>
<svg id="chart" width="900" height="220" viewBox="0 0 900 220" style="background:#fff;border:1px solid #ddd">
 <g id="chart-grid"></g>
 <polyline id="chart-eps" fill="none" stroke="#2f7ed8" stroke-width="2" points=""></polyline>
 <polyline id="chart-sps" fill="none" stroke="#e8710a" stroke-width="2" points=""></polyline>
 <text x="60" y="16" font-size="12" fill="#2f7ed8">evaluations/s</text>
 <text x="170" y="16" font-size="12" fill="#e8710a">samples/s (scaled to the same top)</text>
 <text id="chart-max" x="4" y="30" font-size="11" fill="#777"></text>
 <text id="chart-xmax" x="840" y="214" font-size="11" fill="#777"></text>
</svg>

<h2>Levels (gain and entropy in bits)</h2>
<div id="levels-wrap"><table>
 <thead><tr><th>tree</th><th>level</th><th>nodes</th><th>split</th><th>samples</th><th>mean entropy</th>
 <th>mean gain</th><th>evaluations/s</th><th>seconds</th><th>workers</th></tr></thead>
 <tbody id="levels"></tbody>
</table></div>

<h2>Events</h2>
<table><thead><tr><th class="l">time</th><th class="l">event</th><th>tree</th><th>level</th><th class="l">worker</th><th class="l">message</th></tr></thead>
<tbody id="events"></tbody></table>

<script>
"use strict";
function fmt(v) {
  if (v === null || v === undefined || !isFinite(v)) return "\u2013";
  const a = Math.abs(v);
  if (a >= 1e9) return (v / 1e9).toFixed(2) + " G";
  if (a >= 1e6) return (v / 1e6).toFixed(2) + " M";
  if (a >= 1e3) return (v / 1e3).toFixed(1) + " k";
  return (Math.round(v * 100) / 100).toString();
}
function dur(s) {
  if (s === null || s === undefined || !isFinite(s) || s < 0) return "\u2013";
  s = Math.round(s);
  const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60), r = s % 60;
  return (h ? h + "h " : "") + (h || m ? m + "m " : "") + r + "s";
}
function bytes(b) { return b >= 1048576 ? (b / 1048576).toFixed(1) + " MiB" : (b / 1024).toFixed(1) + " KiB"; }
function set(id, text) { document.getElementById(id).textContent = text; }
function row(tbody, cells, cls) {
  const tr = document.createElement("tr");
  cells.forEach((c, i) => {
    const td = document.createElement("td");
    td.textContent = c;
    if (cls && cls[i]) td.className = cls[i];
    tr.appendChild(td);
  });
  tbody.appendChild(tr);
  return tr;
}
function chart(levels) {
  const W = 900, H = 220, L = 50, R = 10, T = 24, B = 20;
  const pts = levels.filter(l => l.seconds > 0 && l.evaluations > 0);  // not the all-leaf last levels
  const xmax = Math.max(1e-9, ...pts.map(l => l.elapsed_s));
  const emax = Math.max(1e-9, ...pts.map(l => l.evaluations_per_s || 0));
  const smax = Math.max(1e-9, ...pts.map(l => l.samples_per_s || 0));
  const x = t => (L + (W - L - R) * t / xmax).toFixed(1);
  const y = (v, m) => (H - B - (H - T - B) * v / m).toFixed(1);
  document.getElementById("chart-eps").setAttribute("points",
    pts.map(l => x(l.elapsed_s) + "," + y(l.evaluations_per_s || 0, emax)).join(" "));
  document.getElementById("chart-sps").setAttribute("points",
    pts.map(l => x(l.elapsed_s) + "," + y(l.samples_per_s || 0, smax)).join(" "));
  set("chart-max", pts.length ? fmt(emax) : "");
  set("chart-xmax", pts.length ? dur(xmax) : "");
  const grid = document.getElementById("chart-grid");
  if (!grid.childNodes.length) {
    for (let i = 0; i <= 4; ++i) {
      const ln = document.createElementNS("http://www.w3.org/2000/svg", "line");
      const yy = T + (H - T - B) * i / 4;
      ln.setAttribute("x1", L); ln.setAttribute("x2", W - R);
      ln.setAttribute("y1", yy); ln.setAttribute("y2", yy);
      ln.setAttribute("stroke", "#eee");
      grid.appendChild(ln);
    }
  }
}
function render(s) {
  set("job", s.job_id);
  const st = document.getElementById("state");
  st.textContent = s.state;
  st.className = "state-" + s.state;
  set("message", s.message || "");
  set("error", "");
  set("tree", (s.tree + 1) + " / " + s.config.num_trees);
  set("level", s.level + " / " + s.config.max_depth);
  set("nodes", s.level_nodes_done + " / " + s.level_nodes_total);
  set("sps", fmt(s.samples_per_s));
  set("eps", fmt(s.evaluations_per_s));
  set("eta", s.state === "done" ? "done" : dur(s.eta_s));
  set("elapsed", dur(s.elapsed_s));
  set("alive", s.workers.filter(w => w.state === "training" || w.state === "joined").length);
  const pct = Math.round(s.progress * 1000) / 10;
  document.getElementById("bar-fill").style.width = pct + "%";
  set("progress-text", "progress " + pct + " % \u00b7 trees done " + s.trees_done + " of " +
      s.config.num_trees + " \u00b7 forest nodes " + s.forest_nodes + " \u00b7 " + fmt(s.totals.evaluations) +
      " evaluations \u00b7 " + bytes(s.totals.bytes_received) + " received \u00b7 workers lost " +
      s.totals.workers_lost);
  const wb = document.getElementById("workers");
  wb.replaceChildren();
  s.workers.forEach(w => {
    const tr = row(wb, [w.id, w.state, w.frames, w.replies, fmt(w.evaluations_per_s), fmt(w.evaluations),
      bytes(w.bytes_received), w.last_seen_s >= 0 ? w.last_seen_s.toFixed(1) + " s ago" : "\u2013"],
      ["l", "l state-" + w.state]);
    tr.className = "worker-row";
  });
  const lb = document.getElementById("levels");
  lb.replaceChildren();
  s.levels.slice().reverse().forEach(l => row(lb, [l.tree, l.level, l.nodes, l.split, l.samples,
    l.entropy.toFixed(3), l.gain.toFixed(3), fmt(l.evaluations_per_s), l.seconds.toFixed(2), l.workers]));
  const eb = document.getElementById("events");
  eb.replaceChildren();
  s.events.slice(-15).reverse().forEach(e => row(eb, [new Date(e.unix * 1000).toLocaleTimeString(),
    e.event, e.tree, e.level, e.worker, e.message], ["l", "l", "", "", "l", "l"]));
  chart(s.levels);
  document.title = "poseforest " + s.job_id + " \u2013 " + s.state + " " + pct + " %";
}
// With --http-token-file the page is opened as /?token=TOKEN: its fetches send the token as
// "Authorization: Bearer TOKEN" (never stored by the browser: no cookie, no local storage).
const token = (() => {
  const m = /(?:^|[?&])token=([^&]*)/.exec(location.search);
  try { return m ? decodeURIComponent(m[1]) : ""; } catch (e) { return ""; }
})();
let timer = null;
async function poll() {
  try {
    const r = await fetch("status.json", {cache: "no-store", headers: token ? {"Authorization": "Bearer " + token} : {}});
    if (r.status === 401) {
      set("error", "(HTTP 401: the coordinator needs its token: open this page as /?token=TOKEN)");
      return;  // polling again would not help
    }
    if (!r.ok) throw new Error("HTTP " + r.status);
    const s = await r.json();
    render(s);
    if (s.state === "done" || s.state === "failed") return;  // final: stop polling
  } catch (e) {
    set("error", "(coordinator unreachable: " + e.message + ")");
  }
  timer = setTimeout(poll, 1000);
}
poll();
</script>
</body>
</html>
)HTML";
}  // namespace

const std::string& DashboardHtml() {
  static const std::string html = kDashboard;
  return html;
}

proto::http::HttpServer::Handler StatusHandler(const StatusModel* model) {
  return [model](const proto::http::HttpRequest& req) -> proto::http::HttpResponse {
    if (req.path == "/" || req.path == "/index.html")
      return {200, "text/html; charset=utf-8", DashboardHtml()};
    if (req.path == "/status.json") return {200, "application/json", model->Json()};
    if (req.path == "/metrics")
      return {200, "text/plain; version=0.0.4; charset=utf-8",
              model->Prometheus() + (req.server ? proto::http::HttpServerMetrics(*req.server) : "")};
    if (req.path == "/healthz") return {200, "text/plain; charset=utf-8", "ok\n"};
    return {404, "text/plain; charset=utf-8",
            "404 Not Found: " + req.path + " (try /, /status.json, /metrics)\n"};
  };
}

}  // namespace poseforest::coordinator::monitoring
