#pragma once
// DdsNode: one Fast DDS participant of the trainer with a writer and/or a reader per topic,
// carrying serialized protobuf bytes. Fast DDS types stay in dds_node.cpp: callers see bytes,
// topics, events and Status only.
//
// Threading: Fast DDS listener callbacks only record that data is available or push an event;
// samples are taken from the DDS reader history by Receive() on the caller's thread, so a slow
// consumer leaves samples in the (bounded, reliable) history and the writer is flow-controlled.

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "proto/dds/topics.h"
#include "runtime/core/result.h"

namespace poseforest::proto::dds {

/// How the participant reaches its peers.
enum class TransportKind {
  /// Shared memory between processes of one host + UDPv4 (Fast DDS default), multicast discovery.
  kDefault,
  /// Shared memory only: one host, nothing on the network.
  kSharedMemoryOnly,
  /// UDPv4 only (no shared memory), optionally restricted to `interface_whitelist`, discovery via
  /// multicast and/or `initial_peers`. Use for multi-host runs and wire-level tests.
  kUdpOnly,
  /// UDPv4 only, discovery through a Fast DDS discovery server (`fast-discovery-server`) at
  /// `discovery_server`; no multicast needed.
  kDiscoveryClient,
  /// Participant QoS entirely from a Fast DDS XML profile (`xml_file`, `xml_profile`); the
  /// security paths below are still added when set.
  kXmlProfile,
};

/// DDS-Security files (PEM / S/MIME), absolute paths without "file://". All six or none.
struct SecurityFiles {
  std::string identity_ca;           ///< CA that signed every participant certificate
  std::string identity_certificate;  ///< this participant's certificate
  std::string private_key;           ///< its private key (ECDSA P-256)
  std::string permissions_ca;        ///< CA that signed governance and permissions
  std::string governance;            ///< signed governance document (.p7s)
  std::string permissions;           ///< signed permissions document (.p7s)
  bool enabled() const { return !identity_ca.empty(); }
};

struct NodeConfig {
  uint32_t domain_id = 0;
  std::string participant_name = "poseforest";
  TransportKind transport = TransportKind::kDefault;
  /// kUdpOnly / kDiscoveryClient: local IPv4 addresses the participant may use (empty = all).
  std::vector<std::string> interface_whitelist;
  /// kUdpOnly: peers to announce ourselves to, "a.b.c.d" or "a.b.c.d:port". Without a port the
  /// metatraffic unicast ports of participant ids 0..peer_participant_ids-1 of the domain are used.
  /// Multicast discovery stays on as well (harmless where multicast does not pass).
  std::vector<std::string> initial_peers;
  int peer_participant_ids = 4;
  /// RTPS participant id (selects the well-known ports), -1 = automatic. Automatic ids count
  /// up per process and host, so a peer list without ports only reaches ids 0..3: pin the id
  /// when several participants run in one process or host and peers are given without ports.
  /// With shared memory (kDefault, kSharedMemoryOnly, an XML profile of shared memory only that
  /// gives no id) automatic is the lowest id whose ports left no file on this host
  /// (FreshSharedMemoryParticipantId, dds_node_qos.h): a process restarted after a SIGKILL does
  /// not take the dead one's ports.
  int participant_id = -1;
  /// kDiscoveryClient: the servers, "[ID@]a.b.c.d[:port],..." (ParseDiscoveryServers; addresses,
  /// not host names: Create refuses a name); the participant is a client of every one. An entry
  /// with ID@ is `fast-discovery-server -i ID` (GUID prefix DiscoveryServerGuidPrefix(ID)); one
  /// without uses discovery_server_prefix (fast-discovery-server -i 0:
  /// 44.53.00.5f.45.50.52.4f.53.49.4d.41).
  std::string discovery_server = "127.0.0.1:11811";
  std::string discovery_server_prefix = "44.53.00.5f.45.50.52.4f.53.49.4d.41";
  /// kXmlProfile: file and participant profile name.
  std::string xml_file;
  std::string xml_profile;
  /// UDP socket send/receive buffers, bytes. 4 MiB: 1 MiB samples drop heavily with the
  /// ~212 KB default (docs/distributed/README.md). The kernel caps it at net.core.[rw]mem_max.
  uint32_t udp_buffer_bytes = 4u << 20;
  SecurityFiles security;
  /// Lease of AUTOMATIC liveliness on the job and presence topics: a peer that stops (killed,
  /// partitioned) is reported by a kLivelinessLost event at most about this long after.
  std::chrono::milliseconds liveliness_lease{2000};
  /// Liveliness kind of the presence topic. MANUAL_BY_TOPIC (default): each worker's presence
  /// writer is alive while it publishes (or calls AssertLiveliness) at least once per lease.
  /// AUTOMATIC is what the protocol asks for, but Fast DDS 2.9 has a bug (eProsima/Fast-DDS
  /// issue #4373, fixed by PR #4501 on later branches, not in Debian's 2.9.1): while any other remote
  /// participant's AUTOMATIC writer is alive, a killed or cut-off writer is not reported until the
  /// participant lease expires. tests/proto/test_dds_multiprocess.cpp demonstrates both.
  bool presence_manual_liveliness = true;
  /// Participant lease (discovery): a vanished participant is removed after this.
  std::chrono::milliseconds participant_lease{10000};
  /// Keep-all topics (control, replies): samples a reader or writer history holds before the
  /// writer waits for the slowest matched reader (flow control). 0: kKeepAllMaxSamples. Tests
  /// lower it to reproduce a full history at CI size.
  int keep_all_max_samples = 0;
  /// How long one DataWriter::write waits on a full history before Publish looks again whether a
  /// reader is still matched (and, if so, writes again): a slow but live reader is waited for,
  /// a reader that is gone is unmatched by its participant lease and releases the history.
  std::chrono::milliseconds write_block_slice{10000};
  /// Publish gives up (kIo) when a full history has not moved for this long although a reader
  /// stays matched (a peer that is alive but never reads). 0: never gives up.
  std::chrono::milliseconds write_give_up{0};
  /// Told once per write that had to wait a whole slice, and when it went through.
  std::function<void(const std::string&)> log;
  /// Topics this node writes and reads.
  std::vector<Topic> write_topics;
  std::vector<Topic> read_topics;
};

/// Something that happened to the node's endpoints (surfaced from Fast DDS listeners).
struct DdsEvent {
  enum class Kind {
    kWriterMatched,          ///< one of our writers matched a remote reader
    kWriterUnmatched,        ///< ... lost one
    kReaderMatched,          ///< one of our readers matched a remote writer
    kReaderUnmatched,        ///< ... lost one
    kLivelinessLost,         ///< a remote writer stopped asserting liveliness within its lease
    kLivelinessRecovered,    ///< a remote writer became alive (again)
    kParticipantDiscovered,  ///< a remote participant appeared
    kParticipantLost,        ///< a remote participant left or its lease expired
  };
  Kind kind;
  Topic topic = Topic::kJob;  ///< meaningless for participant events
  std::string peer_guid;      ///< remote endpoint (or participant) GUID, "prefix|entity"
  std::string peer_participant;  ///< GUID prefix of the remote participant
  std::string peer_name;      ///< participant name (participant events only)
  int current_count = 0;      ///< matched / alive count after the change
};

const char* EventKindName(DdsEvent::Kind kind);

/// One received sample: the bytes as written, the topic and who wrote it (DDS identity, which
/// the sender cannot choose freely, unlike the Envelope's sender_id).
struct ReceivedSample {
  Topic topic;
  std::vector<uint8_t> bytes;
  std::string writer_guid;
  std::string writer_participant;  ///< GUID prefix
  int64_t source_timestamp_ns = 0;
  double received_s = 0;  ///< when the receiver took it off DDS (its own steady clock; 0: not set)
};

class DdsNode {
 public:
  /// Creates the participant, topics and endpoints. Errors name the failing step; a null
  /// participant with security set usually means unreadable/invalid credential files.
  static core::Result<std::unique_ptr<DdsNode>> Create(const NodeConfig& config);
  ~DdsNode();
  DdsNode(const DdsNode&) = delete;
  DdsNode& operator=(const DdsNode&) = delete;

  /// Writes one sample. Blocks while a reliable keep-all history is full: as long as a matched
  /// reader remains (a busy peer is waited for; a dead one is unmatched when its participant lease
  /// ends, which frees the history), or until write_give_up. Writers of different topics do not
  /// wait for each other (a worker's heartbeats go out while its replies wait).
  core::Status Publish(Topic topic, const void* data, size_t size);
  core::Status Publish(Topic topic, std::string_view bytes) { return Publish(topic, bytes.data(), bytes.size()); }

  /// Next sample from any read topic, waiting up to `timeout`. Topics are served round robin.
  /// Call from one thread (the node's receiving thread); Publish may be called from any thread.
  std::optional<ReceivedSample> Receive(std::chrono::milliseconds timeout);

  /// Next endpoint/participant event, waiting up to `timeout`. At most 4096 are queued (the
  /// oldest are dropped when nobody reads them).
  std::optional<DdsEvent> NextEvent(std::chrono::milliseconds timeout);

  /// Waits until our writer on `topic` has >= n matched readers (and, when we also read it,
  /// our reader >= n matched writers). False on timeout.
  bool WaitForMatch(Topic topic, int n, std::chrono::milliseconds timeout);
  int MatchedReaders(Topic topic) const;
  int MatchedWriters(Topic topic) const;
  /// Waits until the writer on `topic` has every sample acknowledged by all matched readers.
  bool WaitForAcknowledgments(Topic topic, std::chrono::milliseconds timeout);

  /// Asserts the liveliness of our writer on `topic` (needed with manual liveliness when there
  /// is nothing to publish within a lease).
  core::Status AssertLiveliness(Topic topic);

  /// Writes that found a full history and waited at least one write_block_slice (thread-safe).
  uint64_t slow_writes() const;

  /// Our participant's GUID prefix ("01.0f.....").
  std::string participant_guid() const;
  const NodeConfig& config() const;

  struct Impl;

 private:
  explicit DdsNode(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// One discovery server as `fast-discovery-server -i id -l host -p port` runs it.
struct DiscoveryServerAddress {
  int id = 0;             ///< the server's -i, 0..255 (selects its GUID prefix)
  bool id_given = false;  ///< written as ID@...; otherwise id is 0
  /// IPv4 a.b.c.d, or a host name as written (ParseDiscoveryServers accepts names; a
  /// NodeConfig needs addresses: CheckDdsSettings resolves names at start-up).
  std::string host;
  uint32_t port = 11811;  ///< UDP port, 1..65535 (11811 when not written)
};

/// Checks that `host` is an IPv4 address a.b.c.d or, with `allow_names`, a DNS host name (RFC 1123:
/// dot-separated labels of 1..63 letters, digits and hyphens, not starting or ending with a
/// hyphen, at most 253 characters, one trailing dot allowed; a name whose last label is all digits
/// is taken for a mistyped address). IPv6 addresses are refused by name (the transports are UDPv4).
/// InvalidArgument with a message that follows the host ("is not an IPv4 address"): callers put
/// the flag and the entry before it and the form they expect after it.
core::Status CheckHost(const std::string& host, bool allow_names);
/// True for a dotted-quad IPv4 address a.b.c.d (each 0..255).
bool IsIPv4Address(const std::string& host);

/// Parses a comma-separated list of discovery servers, each "[ID@]HOST[:PORT]" (ID 0..255,
/// default 0; HOST an IPv4 address or a host name, CheckHost; PORT 1..65535, default 11811);
/// empty entries are skipped. InvalidArgument naming the offending entry: a bad id, host or
/// port, two entries with the same id or the same host and port, or no entry at all.
core::Result<std::vector<DiscoveryServerAddress>> ParseDiscoveryServers(const std::string& list);

/// The canonical text of `servers`: "a.b.c.d:PORT" for id 0, "ID@a.b.c.d:PORT" otherwise,
/// comma-separated (ParseDiscoveryServers reads it back; one id-0 server is "a.b.c.d:PORT").
std::string FormatDiscoveryServers(const std::vector<DiscoveryServerAddress>& servers);

/// The GUID prefix of `fast-discovery-server -i id` ("44.53.<id hex>.5f.45.50.52.4f.53.49.4d.41",
/// from Fast DDS's get_server_client_default_guidPrefix); empty when id is not 0..255.
std::string DiscoveryServerGuidPrefix(int id);

/// Reads the Fast DDS verbosity from the environment (POSEFOREST_DDS_LOG=error|warning|info)
/// and applies it; defaults to error. Called by DdsNode::Create.
void ConfigureDdsLogging();

}  // namespace poseforest::proto::dds
