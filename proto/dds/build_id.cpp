#include "proto/dds/build_id.h"

#include <cstdlib>

namespace poseforest::proto::detail {
extern const char kCompiledBuildId[];  // build_id_generated.cpp (cmake/build_id.cmake)
}  // namespace poseforest::proto::detail

namespace poseforest::proto::dds {

std::string_view CompiledBuildId() { return detail::kCompiledBuildId; }

std::string BuildId() {
  const char* env = std::getenv("POSEFOREST_BUILD_ID");
  std::string id = env != nullptr && *env != '\0' ? std::string(env) : std::string(CompiledBuildId());
  // Printable ASCII only, so that the wire's string stays valid UTF-8 whatever the variable holds.
  if (id.size() > kMaxBuildIdBytes) id.resize(kMaxBuildIdBytes);
  for (char& c : id)
    if (c < 0x20 || c > 0x7e) c = '?';
  return id;
}

}  // namespace poseforest::proto::dds
