#pragma once
// What the `coordinator` and `worker` commands share: a job file read as `poseforest train` reads
// it, and the DDS flags of a job (the command line's, else the job's `dds` section).

#include <map>
#include <optional>
#include <set>
#include <string>

#include "apps/commands/args.h"
#include "poseforest/v1/job.pb.h"
#include "runtime/core/result.h"

namespace poseforest::apps::commands {

/// The job file's TrainerConfig with its relative paths (pose library, MakeHuman kit, body meshes)
/// resolved against the file's folder, as `poseforest train` does: kIo when the file cannot be
/// read, the parser's error (naming the file) when it does not parse.
core::Result<v1::TrainerConfig> ReadJobConfig(const std::string& path);

/// DDS flag values from a job's `dds` section (job.proto DdsSpec) for the flags the command line
/// leaves out: the domain on its own; the transport settings only when the command line gives no
/// transport flag at all (a command line never mixes with the job's transport). A relative
/// dds_xml is relative to the job file. Errors name the job file and the field.
struct JobDds {
  std::map<std::string, std::string> values;  ///< DDS flag name -> value
  std::string job_path;
  bool transport = false;  ///< the transport settings come from the job
  /// The flag's value: the command line's, else the job's.
  std::optional<std::string> Get(const Args& args, const std::string& name) const {
    if (auto v = args.Get(name)) return v;
    if (const auto it = values.find(name); it != values.end()) return it->second;
    return std::nullopt;
  }
  /// `st` with a note when the failing setting may come from the job.
  core::Status Explain(const core::Status& st) const {
    if (st.ok() || !transport) return st;
    return core::Status(st.code(), st.message() + " (transport settings from the dds section of " + job_path + ")");
  }
};

/// The DDS flag values of `config`'s dds section that the command line (`args`) leaves out.
core::Result<JobDds> JobDdsDefaults(const v1::TrainerConfig& config, const std::string& job_path, const Args& args);

/// `names` plus the DDS value options, for Args.
std::set<std::string> WithDdsOptions(std::set<std::string> names);

/// The DDS flags' part of the usage texts.
inline constexpr const char* kDdsUsage =
    "  DDS transport (docs/distributed/README.md; the same on every participant of a job):\n"
    "    --profile shm|udp|default     built-in transports: shared memory (default), UDP only, both\n"
    "    --peers HOST[:PORT],...       --profile udp: initial peers (hosts without multicast)\n"
    "    --interfaces IP,...           --profile udp or --discovery-server: local IPv4 addresses\n"
    "    --dds-xml FILE --dds-profile NAME   a Fast DDS XML participant profile instead\n"
    "                                  (deploy/fastdds/profiles.xml); env POSEFOREST_DDS_XML and\n"
    "                                  POSEFOREST_DDS_PROFILE stand in for them unless a transport\n"
    "                                  flag is given\n"
    "    --discovery-server [ID@]HOST[:PORT],...  discovery through `fast-discovery-server -i ID`\n"
    "                                  (UDP; ID 0..255, default 0; port 11811): a client of every\n"
    "                                  server listed (redundant servers: 0@IP0,1@IP1)\n"
    "    HOST: an IPv4 address or a host name, resolved (IPv4) once at start-up and shown; a name\n"
    "    that does not resolve exits 2. IPv6 is not supported.\n"
    "    --security DIR                DDS-Security (authentication, access control, encryption):\n"
    "                                  DIR/cert.pem, key.pem, permissions.p7s and identity_ca.pem,\n"
    "                                  permissions_ca.pem, governance.p7s in DIR or DIR/..\n"
    "                                  (deploy/security/make-test-ca.sh OUT NAME -> --security OUT/NAME)\n";

}  // namespace poseforest::apps::commands
