#include "worker/distributed/dist_common.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>

namespace poseforest::dist {

using core::ErrorCode;
using core::Result;
using core::Status;

Result<dds::TransportKind> ParseProfile(const std::string& name) {
  if (name == "shm") return dds::TransportKind::kSharedMemoryOnly;
  if (name == "udp") return dds::TransportKind::kUdpOnly;
  if (name == "default") return dds::TransportKind::kDefault;
  return Status(ErrorCode::kInvalidArgument, "--profile " + name + ": expected shm, udp or default");
}

dds::NodeConfig MakeNodeConfig(uint32_t domain, dds::TransportKind transport, bool coordinator,
                               const std::string& name, std::chrono::milliseconds lease,
                               const std::vector<std::string>& peers,
                               const std::vector<std::string>& interfaces, const TransportExtras& extras) {
  dds::NodeConfig c;
  c.domain_id = domain;
  c.participant_name = name;
  c.liveliness_lease = lease;
  DdsFlags flags;
  flags.transport = transport;
  flags.peers = peers;
  flags.interfaces = interfaces;
  flags.extras = extras;
  ApplyDdsFlags(flags, &c);
  using dds::Topic;
  if (coordinator) {
    c.write_topics = {Topic::kJob, Topic::kControl, Topic::kStatus};
    c.read_topics = {Topic::kReplies, Topic::kPresence};
  } else {
    c.write_topics = {Topic::kReplies, Topic::kPresence};
    c.read_topics = {Topic::kJob, Topic::kControl, Topic::kStatus};
  }
  return c;
}

Result<std::vector<std::string>> ParseAddressList(const std::string& value, const std::string& flag,
                                                  bool allow_port, bool allow_names) {
  std::vector<std::string> out;
  const std::string form = std::string(allow_names ? "a.b.c.d or a host name" : "a.b.c.d") +
                           (allow_port ? ", with an optional :port" : "");
  auto bad = [&](const std::string& item, const std::string& why) {
    return Status(ErrorCode::kInvalidArgument, "--" + flag + " " + value + ": '" + item + "' " + why);
  };
  size_t start = 0;
  while (start <= value.size()) {
    const size_t comma = std::min(value.find(',', start), value.size());
    const std::string item = value.substr(start, comma - start);
    start = comma + 1;
    if (item.empty()) continue;
    // More than one ':' (or a '['): an IPv6 address, which CheckHost refuses with its reason.
    const bool v6 = item.find('[') != std::string::npos || item.find(':') != item.rfind(':');
    const size_t colon = v6 ? std::string::npos : item.find(':');
    if (Status host = dds::CheckHost(item.substr(0, colon), allow_names); !host.ok())
      return bad(item, host.message() + " (expected " + form + ")");
    if (colon != std::string::npos) {
      const std::string port = item.substr(colon + 1);
      const bool ok = allow_port && !port.empty() && port.size() <= 5 &&
                      port.find_first_not_of("0123456789") == std::string::npos && std::stoi(port) > 0 &&
                      std::stoi(port) < 65536;
      if (!ok)
        return bad(item, allow_port
                             ? "has port '" + port + "': expected 1..65535"
                             : "has a port; --" + flag + " takes addresses only (expected " + form + ")");
    }
    out.push_back(item);
  }
  if (out.empty()) return Status(ErrorCode::kInvalidArgument, "--" + flag + ": no address given");
  return out;
}

void EncodeWireRuns(const worker::NodeHistogram& hist, const worker::NodePlan& plan, int num_parts,
                    google::protobuf::RepeatedField<uint64_t>* runs) {
  runs->Clear();
  const int slots = hist.num_slots, bins = hist.num_bins;
  // Slots in ascending part order: the order of their cells inside a wire row.
  std::vector<std::pair<int, int>> order;  // (part, slot)
  for (int p = 0; p < num_parts && p < int(plan.part_slot.size()); ++p)
    if (plan.part_slot[size_t(p)] != 0xFF && plan.part_slot[size_t(p)] < slots)
      order.emplace_back(p, plan.part_slot[size_t(p)]);
  // Same runs as EncodeHistogramRuns over the dense tensor: a literal run goes on over single
  // zeros (the next non-zero cell 2 further) and ends before two or more zeros.
  uint64_t next = 0;   // tensor position after the last cell written
  int len_index = -1;  // index of the open run's length entry, -1 when none is open
  auto emit = [&](uint64_t pos, uint32_t v) {
    if (len_index >= 0 && pos == next + 1) {  // an isolated zero stays inside the run
      runs->Add(0);
    } else if (len_index < 0 || pos != next) {
      if (len_index >= 0) runs->Set(len_index, uint64_t(runs->size() - len_index - 1));
      runs->Add(pos - next);
      len_index = runs->size();
      runs->Add(0);  // length, set when the run ends
    }
    runs->Add(v);
    next = pos + 1;
  };
  std::vector<uint32_t> row(size_t(bins) * size_t(slots));
  for (int k = 0; k < hist.num_candidates; ++k) {
    const uint32_t* c = row.data();
    if (hist.sample_bins)
      hist.CandidateCounts(k, row.data());
    else
      c = hist.counts.data() + size_t(k) * row.size();
    for (int b = 0; b < bins; ++b) {
      const uint64_t base = (uint64_t(k) * uint64_t(bins) + uint64_t(b)) * uint64_t(num_parts);
      for (const auto& [part, slot] : order)
        if (const uint32_t v = c[size_t(b) * size_t(slots) + size_t(slot)]; v != 0)
          emit(base + uint64_t(part), v);
    }
  }
  if (len_index >= 0) runs->Set(len_index, uint64_t(runs->size() - len_index - 1));
}

bool AddWireRuns(const google::protobuf::RepeatedField<uint64_t>& runs, const dds::HistogramDims& dims,
                 const worker::NodePlan& plan, worker::NodeHistogram* hist) {
  const uint64_t cells = dims.cells();
  const uint64_t parts = dims.num_parts, slots = uint64_t(hist->num_slots);
  if (uint64_t(hist->num_candidates) * uint64_t(hist->num_bins) * parts != cells ||
      plan.part_slot.size() < parts)
    return false;
  uint64_t pos = 0;
  const int n = runs.size();
  for (int i = 0; i < n;) {
    pos += runs.Get(i++);
    if (i >= n) break;
    const uint64_t lit = runs.Get(i++);
    if (lit == 0 || lit > uint64_t(n - i) || pos > cells || lit > cells - pos) return false;
    for (uint64_t j = 0; j < lit; ++j, ++pos) {
      const uint64_t v = runs.Get(i++);
      if (v == 0) continue;
      if (v > 0xFFFFFFFFull) return false;
      const uint8_t slot = plan.part_slot[size_t(pos % parts)];
      if (slot == 0xFF) return false;
      hist->counts[size_t((pos / parts) * slots + slot)] += uint32_t(v);
    }
  }
  return pos <= cells;
}

void SetFeatureSplit(const core::FeatureOffsets& f, int32_t cut, uint32_t left_child, uint32_t candidate,
                     v1::FeatureSplit* out) {
  out->set_ux(f.ux);
  out->set_uy(f.uy);
  out->set_vx(f.vx);
  out->set_vy(f.vy);
  out->set_threshold(float(double(cut) + 0.5));
  out->set_candidate_index(candidate);
  out->set_left_child(left_child);
}

Status GetFeatureSplit(const v1::FeatureSplit& s, core::FeatureOffsets* f, int32_t* cut) {
  const double t = double(s.threshold()) - 0.5;
  if (!std::isfinite(t) || std::abs(t) > double(1 << 22) || t != std::floor(t))
    return Status(ErrorCode::kInvalidArgument,
                  "threshold " + std::to_string(s.threshold()) + " is not an integer + 0.5");
  f->ux = int16_t(s.ux());
  f->uy = int16_t(s.uy());
  f->vx = int16_t(s.vx());
  f->vy = int16_t(s.vy());
  *cut = int32_t(t);
  return Status::Ok();
}

double NowSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::string DefaultWorkerId() {
  static const uint32_t base = uint32_t(std::random_device{}());
  static std::atomic<uint32_t> count{0};
  char host[256] = {};
  ::gethostname(host, sizeof host - 1);
  char suffix[16];
  std::snprintf(suffix, sizeof suffix, "%06x", unsigned((base + count++) & 0xFFFFFF));
  return "worker-" + std::string(host) + "-" + std::to_string(::getpid()) + "-" + suffix;
}

}  // namespace poseforest::dist
