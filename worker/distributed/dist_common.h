#pragma once
// Pieces the distributed worker and coordinator share: transport profiles and the conversion
// between the engine's NodeHistogram (slots) and the wire's dense counts[candidate][bin][part]
// tensor. Every message they exchange is poseforest.v1 (proto/poseforest/v1/wire.proto).

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "poseforest/v1/wire.pb.h"
#include "proto/dds/dds_node.h"
#include "proto/dds/histogram_codec.h"
#include "runtime/core/result.h"
#include "worker/distributed/dds_flags.h"
#include "worker/histogram_builder.h"

namespace poseforest::dist {

/// Transport profile names accepted by --profile: "shm" (shared memory only), "udp" (UDPv4 only,
/// loopback + interfaces), "default" (shared memory + UDP). Errors name the bad value.
core::Result<dds::TransportKind> ParseProfile(const std::string& name);

/// Participant settings of a trainer node on `domain` with `transport`, reading/writing the topics
/// of a coordinator (`coordinator` true) or a worker. `lease`: presence liveliness lease.
/// kUdpOnly: `peers` ("a.b.c.d[:port]") replace the default initial peer 127.0.0.1 (hosts without
/// multicast: workers list the coordinator), `interfaces` restricts the local IPv4 addresses used
/// (kUdpOnly, kDiscoveryClient). `extras`: the XML profile (kXmlProfile), the discovery server
/// (kDiscoveryClient) and DDS-Security credentials (any transport) of the --dds-xml,
/// --discovery-server and --security flags (dds_flags.h).
dds::NodeConfig MakeNodeConfig(uint32_t domain, dds::TransportKind transport, bool coordinator,
                               const std::string& name, std::chrono::milliseconds lease,
                               const std::vector<std::string>& peers = {},
                               const std::vector<std::string>& interfaces = {},
                               const TransportExtras& extras = {});

/// Splits a comma-separated --peers / --interfaces value; InvalidArgument naming `flag` and the
/// entry for one that is not an IPv4 address, or with `allow_names` a host name (dds::CheckHost;
/// the names are kept as written: ParseDdsFlags resolves them), with an optional :port when
/// `allow_port`. IPv6 addresses are refused by name.
core::Result<std::vector<std::string>> ParseAddressList(const std::string& value, const std::string& flag,
                                                        bool allow_port, bool allow_names = false);

/// dds::EncodeHistogramRuns of the dense wire tensor (num_candidates x num_bins x num_parts; slot
/// -> part through plan.part_slot), the same runs to the byte, from the histogram's non-zero counts only: no dense num_parts-wide tensor is built or scanned, so
/// the cost follows candidates x bins x parts present (and the samples for per-sample bins).
void EncodeWireRuns(const worker::NodeHistogram& hist, const worker::NodePlan& plan, int num_parts,
                    google::protobuf::RepeatedField<uint64_t>* runs);

/// Adds a run-encoded wire tensor (dds/histogram_codec.h layout, `dims`) into `hist` without
/// expanding it. False when the runs overrun the tensor or count a part absent from the node.
bool AddWireRuns(const google::protobuf::RepeatedField<uint64_t>& runs, const dds::HistogramDims& dims,
                 const worker::NodePlan& plan, worker::NodeHistogram* hist);

/// Sets the 4 offsets + threshold of a wire FeatureSplit; threshold = cut + 0.5 (exact in float
/// for |cut| < 2^22).
void SetFeatureSplit(const core::FeatureOffsets& f, int32_t cut, uint32_t left_child, uint32_t candidate,
                     v1::FeatureSplit* out);
/// Inverse of SetFeatureSplit; InvalidArgument for a threshold that is not k + 0.5.
core::Status GetFeatureSplit(const v1::FeatureSplit& s, core::FeatureOffsets* f, int32_t* cut);

/// Seconds on a monotonic clock.
double NowSeconds();

/// A worker id for a worker given none: "worker-HOST-PID-XXXXXX". Host and pid alone collide
/// between containers on the host network (each worker is pid 1 on the same hostname) and
/// between workers of one process: the coordinator would take two workers for one. XXXXXX (24
/// bits, hex) is a random number drawn once per process plus a per-process counter, so two ids
/// of one process always differ and those of different processes differ but by chance (2^-24).
std::string DefaultWorkerId();

}  // namespace poseforest::dist
