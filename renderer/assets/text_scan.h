#pragma once
// Small helpers of the line-based asset readers (MakeHuman .target/.mhclo/.obj text): numbers,
// whitespace-separated words, lines with their numbers. Internal to renderer/assets.

#include <charconv>
#include <cmath>
#include <string_view>
#include <system_error>
#include <vector>

namespace poseforest::renderer::assets::text {

/// A finite decimal number, the whole word (a leading '+' allowed).
inline bool ParseNum(std::string_view w, double* out) {
  if (!w.empty() && w.front() == '+') w.remove_prefix(1);
  auto [p, ec] = std::from_chars(w.data(), w.data() + w.size(), *out);
  return ec == std::errc() && p == w.data() + w.size() && std::isfinite(*out);
}

/// The words of a line, split at spaces, tabs and carriage returns.
inline std::vector<std::string_view> Words(std::string_view line) {
  std::vector<std::string_view> out;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r') ++j;
    if (j > i) out.push_back(line.substr(i, j - i));
    i = j;
  }
  return out;
}

/// Calls f(line, line_number from 1) for each line of `text` until f returns false.
template <typename F>
void ForEachLine(std::string_view text, F&& f) {
  size_t pos = 0;
  int line_no = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    ++line_no;
    if (!f(text.substr(pos, end - pos), line_no)) return;
    pos = end + 1;
  }
}

}  // namespace poseforest::renderer::assets::text
