#pragma once
// Status / Result<T>: the error type of everything that reads files, messages or user input.
// Internal invariants use POSEFOREST_CHECK (aborts); never use it for input.

#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <utility>

namespace poseforest::core {

/// Broad class of failure, so callers can react without parsing messages.
enum class ErrorCode {
  kOk = 0,
  kInvalidArgument,  ///< the caller or the user gave a bad value
  kDataLoss,         ///< a file or message is corrupt or truncated
  kVersionMismatch,  ///< a file of another major format version
  kIo,               ///< the OS failed to open/read/write
  kNotFound,
  kUnimplemented,
  kInternal,
};

/// Name of a code, for messages ("DataLoss").
const char* ErrorCodeName(ErrorCode code);

/// An error code plus a message that names the file/sender and the problem.
class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(ErrorCode code, std::string message) : code_(code), message_(std::move(message)) {}
  static Status Ok() { return {}; }

  bool ok() const { return code_ == ErrorCode::kOk; }
  ErrorCode code() const { return code_; }
  const std::string& message() const { return message_; }
  /// "DataLoss: forest.pff: checksum mismatch ..."
  std::string ToString() const;

 private:
  ErrorCode code_ = ErrorCode::kOk;
  std::string message_;
};

/// A value or a Status explaining why there is none.
template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : value_(std::move(value)) {}  // NOLINT: implicit by design
  Result(Status status) : status_(std::move(status)) {  // NOLINT
    if (status_.ok()) status_ = Status(ErrorCode::kInternal, "Result built from an OK status");
  }

  bool ok() const { return value_.has_value(); }
  const Status& status() const { return status_; }
  T& value() & { return *value_; }
  const T& value() const& { return *value_; }
  T&& value() && { return std::move(*value_); }
  T* operator->() { return &*value_; }
  const T* operator->() const { return &*value_; }
  T& operator*() & { return *value_; }
  const T& operator*() const& { return *value_; }

 private:
  std::optional<T> value_;
  Status status_;
};

[[noreturn]] void CheckFailed(const char* expr, const char* file, int line, const char* msg);

}  // namespace poseforest::core

#define POSEFOREST_CHECK(cond)                                                  \
  do {                                                                          \
    if (!(cond)) ::poseforest::core::CheckFailed(#cond, __FILE__, __LINE__, ""); \
  } while (0)
#define POSEFOREST_CHECK_MSG(cond, msg)                                            \
  do {                                                                             \
    if (!(cond)) ::poseforest::core::CheckFailed(#cond, __FILE__, __LINE__, (msg)); \
  } while (0)

/// Propagate a non-OK Status from an expression returning Status.
#define POSEFOREST_RETURN_IF_ERROR(expr)       \
  do {                                         \
    ::poseforest::core::Status _st = (expr);   \
    if (!_st.ok()) return _st;                 \
  } while (0)
