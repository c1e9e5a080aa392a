#include "renderer/assets/json_lite.h"

#include <cctype>
#include <charconv>
#include <cmath>

namespace poseforest::renderer::assets::json {
namespace {

class Parser {
 public:
  Parser(std::string_view t, const std::string& source) : t_(t), source_(source) {}

  core::Result<Value> Run() {
    Value v;
    if (!ParseValue(&v, 0)) return Error();
    Skip();
    if (p_ != t_.size()) {
      err_ = "trailing characters";
      return Error();
    }
    return v;
  }

 private:
  core::Status Error() const {
    return core::Status(core::ErrorCode::kDataLoss,
                        source_ + ": JSON error at byte " + std::to_string(p_) + ": " + err_);
  }
  void Skip() {
    while (p_ < t_.size() && (t_[p_] == ' ' || t_[p_] == '\n' || t_[p_] == '\r' || t_[p_] == '\t')) ++p_;
  }
  bool Fail(const char* what) {
    err_ = what;
    return false;
  }
  bool Literal(std::string_view word) {
    if (t_.substr(p_, word.size()) != word) return Fail("bad literal");
    p_ += word.size();
    return true;
  }
  bool ParseString(std::string* out) {
    if (p_ >= t_.size() || t_[p_] != '"') return Fail("expected a string");
    ++p_;
    while (p_ < t_.size() && t_[p_] != '"') {
      char c = t_[p_++];
      if (c == '\\') {
        if (p_ >= t_.size()) return Fail("unterminated escape");
        const char e = t_[p_++];
        switch (e) {
          case 'n':
            c = '\n';
            break;
          case 't':
            c = '\t';
            break;
          case 'r':
            c = '\r';
            break;
          case 'b':
            c = '\b';
            break;
          case 'f':
            c = '\f';
            break;
          case 'u': {
            if (p_ + 4 > t_.size()) return Fail("bad \\u escape");
            unsigned code = 0;
            auto [ptr, ec] = std::from_chars(t_.data() + p_, t_.data() + p_ + 4, code, 16);
            if (ec != std::errc() || ptr != t_.data() + p_ + 4) return Fail("bad \\u escape");
            p_ += 4;
            // Names in the rig files are ASCII; keep other code points as UTF-8 (BMP only).
            if (code < 0x80) {
              c = char(code);
            } else if (code < 0x800) {
              out->push_back(char(0xC0 | (code >> 6)));
              c = char(0x80 | (code & 0x3F));
            } else {
              out->push_back(char(0xE0 | (code >> 12)));
              out->push_back(char(0x80 | ((code >> 6) & 0x3F)));
              c = char(0x80 | (code & 0x3F));
            }
            break;
          }
          default:
            c = e;
            break;
        }
      }
      out->push_back(c);
    }
    if (p_ >= t_.size()) return Fail("unterminated string");
    ++p_;
    return true;
  }
  bool ParseValue(Value* v, int depth) {
    if (depth > 64) return Fail("nesting too deep");
    Skip();
    if (p_ >= t_.size()) return Fail("unexpected end of input");
    const char c = t_[p_];
    if (c == '{') {
      v->kind = Value::Kind::kObject;
      ++p_;
      Skip();
      if (p_ < t_.size() && t_[p_] == '}') return ++p_, true;
      while (true) {
        Skip();
        std::string key;
        if (!ParseString(&key)) return false;
        Skip();
        if (p_ >= t_.size() || t_[p_] != ':') return Fail("expected ':'");
        ++p_;
        Value member;
        if (!ParseValue(&member, depth + 1)) return false;
        v->object.emplace_back(std::move(key), std::move(member));
        Skip();
        if (p_ < t_.size() && t_[p_] == ',') {
          ++p_;
          continue;
        }
        if (p_ < t_.size() && t_[p_] == '}') return ++p_, true;
        return Fail("expected ',' or '}'");
      }
    }
    if (c == '[') {
      v->kind = Value::Kind::kArray;
      ++p_;
      Skip();
      if (p_ < t_.size() && t_[p_] == ']') return ++p_, true;
      while (true) {
        Value item;
        if (!ParseValue(&item, depth + 1)) return false;
        v->array.push_back(std::move(item));
        Skip();
        if (p_ < t_.size() && t_[p_] == ',') {
          ++p_;
          continue;
        }
        if (p_ < t_.size() && t_[p_] == ']') return ++p_, true;
        return Fail("expected ',' or ']'");
      }
    }
    if (c == '"') {
      v->kind = Value::Kind::kString;
      return ParseString(&v->string);
    }
    if (c == 't') return v->kind = Value::Kind::kBool, v->boolean = true, Literal("true");
    if (c == 'f') return v->kind = Value::Kind::kBool, v->boolean = false, Literal("false");
    if (c == 'n') return v->kind = Value::Kind::kNull, Literal("null");
    size_t e = p_;
    while (e < t_.size() && (std::isdigit(static_cast<unsigned char>(t_[e])) || t_[e] == '-' ||
                             t_[e] == '+' || t_[e] == '.' || t_[e] == 'e' || t_[e] == 'E'))
      ++e;
    if (e == p_) return Fail("unexpected character");
    auto [ptr, ec] = std::from_chars(t_.data() + p_, t_.data() + e, v->number);
    if (ec != std::errc() || ptr != t_.data() + e || !std::isfinite(v->number)) return Fail("bad number");
    v->kind = Value::Kind::kNumber;
    p_ = e;
    return true;
  }

  std::string_view t_;
  const std::string& source_;
  size_t p_ = 0;
  std::string err_;
};

}  // namespace

core::Result<Value> Parse(std::string_view text, const std::string& source) {
  return Parser(text, source).Run();
}

}  // namespace poseforest::renderer::assets::json
