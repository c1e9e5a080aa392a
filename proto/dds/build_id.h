#pragma once
// The identity of this build that the training service compares: the coordinator puts its own in
// the JobAnnouncement and admits only workers whose WorkerHello reports the same one, and a worker
// refuses a job announced by another build. A different build may render and split differently,
// so a forest trained by mixed builds would depend on which worker took which frames, and the
// same job seed would no longer give the same forest (docs/distributed/README.md, "Several hosts").

#include <cstddef>
#include <string>
#include <string_view>

namespace poseforest::proto::dds {

/// Longest identity BuildId() returns and the message gate accepts.
inline constexpr size_t kMaxBuildIdBytes = 256;

/// The compiled identity: "poseforest VERSION COMMIT COMPILER PROCESSOR", e.g. "poseforest 0.4.0
/// a7441d6f1e2b GNU-12.2.0 x86_64" (cmake/build_id.cmake; COMMIT is "no-git" without git).
std::string_view CompiledBuildId();

/// The identity this process reports and compares: POSEFOREST_BUILD_ID when set and not empty
/// (to admit builds that are known to train alike, e.g. the same commit with a local change on
/// one host: set the same value on every host), else CompiledBuildId(). At most kMaxBuildIdBytes,
/// printable ASCII (other bytes become '?').
std::string BuildId();

}  // namespace poseforest::proto::dds
