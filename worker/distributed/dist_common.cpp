#include "worker/distributed/dist_common.h"

#include <cmath>
#include <limits>

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
                               const std::string& name, std::chrono::milliseconds lease) {
  dds::NodeConfig c;
  c.domain_id = domain;
  c.participant_name = name;
  c.transport = transport;
  c.liveliness_lease = lease;
  if (transport == dds::TransportKind::kUdpOnly) c.initial_peers = {"127.0.0.1"}, c.peer_participant_ids = 16;
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

void AttachExt(const google::protobuf::Message& ext, google::protobuf::Message* body) {
  body->MergeFromString(ext.SerializeAsString());
}

Status ReadExt(const google::protobuf::Message& body, google::protobuf::Message* ext,
               const std::string& what) {
  ext->Clear();
  if (!ext->ParseFromString(body.SerializeAsString()))
    return Status(ErrorCode::kDataLoss, what + ": extension fields do not parse");
  return Status::Ok();
}

std::vector<uint32_t> ToWireCounts(const worker::NodeHistogram& hist, const worker::NodePlan& plan,
                                   int num_parts) {
  const worker::NodeHistogram dense = hist.sample_bins ? hist.ToDense() : hist;
  const size_t k_count = size_t(dense.num_candidates), bins = size_t(dense.num_bins),
               slots = size_t(dense.num_slots);
  std::vector<int> part_of_slot(slots, 0);
  for (int p = 0; p < num_parts && p < int(plan.part_slot.size()); ++p)
    if (plan.part_slot[size_t(p)] != 0xFF) part_of_slot[plan.part_slot[size_t(p)]] = p;
  std::vector<uint32_t> wire(k_count * bins * size_t(num_parts), 0);
  if (dense.counts.empty()) return wire;
  for (size_t kb = 0; kb < k_count * bins; ++kb)
    for (size_t s = 0; s < slots; ++s)
      wire[kb * size_t(num_parts) + size_t(part_of_slot[s])] = dense.counts[kb * slots + s];
  return wire;
}

bool AddWireCounts(const std::vector<uint32_t>& wire, const worker::NodePlan& plan, int num_parts,
                   worker::NodeHistogram* hist) {
  const size_t kb_count = size_t(hist->num_candidates) * size_t(hist->num_bins),
               slots = size_t(hist->num_slots);
  for (size_t kb = 0; kb < kb_count; ++kb) {
    const uint32_t* row = wire.data() + kb * size_t(num_parts);
    for (int p = 0; p < num_parts; ++p) {
      if (row[p] == 0) continue;
      const uint8_t slot = plan.part_slot[size_t(p)];
      if (slot == 0xFF) return false;
      hist->counts[kb * slots + slot] += row[p];
    }
  }
  return true;
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

}  // namespace poseforest::dist
