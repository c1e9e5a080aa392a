#include "runtime/core/result.h"

namespace poseforest::core {

const char* ErrorCodeName(ErrorCode code) {
  switch (code) {
    case ErrorCode::kOk: return "Ok";
    case ErrorCode::kInvalidArgument: return "InvalidArgument";
    case ErrorCode::kDataLoss: return "DataLoss";
    case ErrorCode::kVersionMismatch: return "VersionMismatch";
    case ErrorCode::kIo: return "Io";
    case ErrorCode::kNotFound: return "NotFound";
    case ErrorCode::kUnimplemented: return "Unimplemented";
    case ErrorCode::kInternal: return "Internal";
  }
  return "Unknown";
}

std::string Status::ToString() const {
  if (ok()) return "Ok";
  return std::string(ErrorCodeName(code_)) + ": " + message_;
}

void CheckFailed(const char* expr, const char* file, int line, const char* msg) {
  std::fprintf(stderr, "poseforest: internal check failed at %s:%d: %s %s\n", file, line, expr, msg);
  std::abort();
}

}  // namespace poseforest::core
