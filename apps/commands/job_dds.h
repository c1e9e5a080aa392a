#pragma once
// What the `coordinator` and `worker` commands share: a job file read as `poseforest train` reads
// it, and the DDS flags of a job (the command line's, else the job's `dds` section).

#include <optional>
#include <string>

#include "poseforest/v1/job.pb.h"
#include "proto/dds/dds_flags.h"
#include "runtime/core/result.h"

namespace poseforest::apps::commands {

/// The job file's TrainerConfig with its relative paths (pose library, MakeHuman kit, body meshes)
/// resolved against the file's folder, as `poseforest train` does: kIo when the file cannot be
/// read, the parser's error (naming the file) when it does not parse.
core::Result<v1::TrainerConfig> ReadJobConfig(const std::string& path);

/// DDS settings from a job's `dds` section (job.proto DdsSpec) for the flags the command line
/// leaves out: the domain on its own; the transport settings only when the command line gives no
/// transport flag at all (a command line never mixes with the job's transport). A relative
/// dds_xml is relative to the job file. Errors name the job file and the field.
struct JobDds {
  proto::dds::DdsSettings settings;  ///< the command line's, else the job's
  std::optional<long> domain;        ///< the job's domain where the command line gives none
  std::string job_path;
  bool transport = false;  ///< the transport settings come from the job
  /// `st` with a note when the failing setting may come from the job.
  core::Status Explain(const core::Status& st) const {
    if (st.ok() || !transport) return st;
    return core::Status(st.code(), st.message() + " (transport settings from the dds section of " + job_path + ")");
  }
};

/// The DDS settings of `command_line`, completed from `config`'s dds section; `domain_given`:
/// the command line gives --domain.
core::Result<JobDds> JobDdsDefaults(const v1::TrainerConfig& config, const std::string& job_path,
                                    const proto::dds::DdsSettings& command_line, bool domain_given);

}  // namespace poseforest::apps::commands
