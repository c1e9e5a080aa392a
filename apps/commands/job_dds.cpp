#include "apps/commands/job_dds.h"

#include <filesystem>
#include <fstream>
#include <sstream>

#include "engine/job_spec.h"
#include "proto/dds/dds_flags.h"
#include "runtime/core/forest_format.h"

namespace poseforest::apps::commands {

using core::Status;

/// The job file's TrainerConfig with its relative paths (pose library, MakeHuman kit, body meshes)
/// resolved against the file's folder, as `poseforest train` does: kIo when the file cannot be
/// read, the parser's error (naming the file) when it does not parse.
core::Result<v1::TrainerConfig> ReadJobConfig(const std::string& path) {
  auto text = core::ReadFileText(path);
  if (!text.ok()) return text.status();
  auto config = engine::ParseJobText(*text, path);
  if (!config.ok()) return config.status();
  engine::ResolveJobPaths(path, &*config);
  return config;
}

core::Result<JobDds> JobDdsDefaults(const v1::TrainerConfig& config, const std::string& job_path,
                                    const proto::dds::DdsSettings& command_line, bool domain_given) {
  JobDds out;
  out.settings = command_line;
  out.job_path = job_path;
  if (!config.has_dds()) return out;
  const v1::DdsSpec& d = config.dds();
  auto bad = [&](const std::string& m) { return Status(core::ErrorCode::kInvalidArgument, job_path + ": dds." + m); };
  if (d.has_domain()) {
    if (d.domain() > 232) return bad("domain " + std::to_string(d.domain()) + " is not a DDS domain id (0..232)");
    if (!domain_given) out.domain = long(d.domain());
  }
  if (command_line.transport_given()) return out;  // the command line's transport, whole
  auto join = [](const auto& items) {
    std::string j;
    for (const std::string& i : items) j += (j.empty() ? "" : ",") + i;
    return j;
  };
  proto::dds::DdsSettings& s = out.settings;
  if (d.has_profile()) {
    if (d.profile() != "shm" && d.profile() != "udp" && d.profile() != "default")
      return bad("profile \"" + d.profile() + "\" is not shm, udp or default");
    s.profile = d.profile();
  }
  for (const std::string& p : d.peers())
    if (p.empty() || p.find(',') != std::string::npos) return bad("peers: \"" + p + "\" is not one IP[:PORT]");
  for (const std::string& i : d.interfaces())
    if (i.empty() || i.find(',') != std::string::npos) return bad("interfaces: \"" + i + "\" is not one address");
  if (d.peers_size() > 0) s.peers = join(d.peers());
  if (d.interfaces_size() > 0) s.interfaces = join(d.interfaces());
  if (d.has_discovery_server()) s.discovery_server = d.discovery_server();
  if (d.has_dds_xml()) {
    std::filesystem::path xml = d.dds_xml();
    if (xml.empty()) return bad("dds_xml is empty");
    if (xml.is_relative()) xml = (std::filesystem::path(job_path).parent_path() / xml).lexically_normal();
    s.dds_xml = xml.string();
  }
  if (d.has_dds_profile()) s.dds_profile = d.dds_profile();
  out.transport = s.transport_given();
  return out;
}

}  // namespace poseforest::apps::commands
