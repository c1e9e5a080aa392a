#pragma once
// A minimal JSON reader for the MakeHuman rig files (.mhskel, .mhw). Internal to the assets
// library: no writer, numbers as double, objects keep insertion order.

#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "runtime/core/result.h"

namespace poseforest::renderer::assets::json {

struct Value {
  enum class Kind { kNull, kBool, kNumber, kString, kArray, kObject } kind = Kind::kNull;
  bool boolean = false;
  double number = 0;
  std::string string;
  std::vector<Value> array;
  std::vector<std::pair<std::string, Value>> object;

  /// Member `key` of an object, or nullptr.
  const Value* Find(std::string_view key) const {
    if (kind != Kind::kObject) return nullptr;
    for (const auto& [k, v] : object)
      if (k == key) return &v;
    return nullptr;
  }
  bool IsObject() const { return kind == Kind::kObject; }
  bool IsArray() const { return kind == Kind::kArray; }
  bool IsNumber() const { return kind == Kind::kNumber; }
  bool IsString() const { return kind == Kind::kString; }
};

/// Parses `text`; errors name `source` and the byte offset.
core::Result<Value> Parse(std::string_view text, const std::string& source);

}  // namespace poseforest::renderer::assets::json
