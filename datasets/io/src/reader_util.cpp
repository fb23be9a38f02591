#include "reader_util.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <system_error>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/input_limits.hpp"

namespace planeslam::datasets::detail {

std::int64_t MaxInputFileBytes() {
  const InputLimits& limits = GlobalInputLimits();
  // 32 bytes per point covers x y z + rgb + normals as float32 with room for headers/ascii
  // text is longer per point, so allow 4x that (ascii PCD prints ~10 chars per number).
  const std::int64_t per_point = 128;
  const std::int64_t most = std::max(limits.max_pixels, limits.max_points);
  return most * per_point + (1 << 20);
}

std::ifstream OpenWholeFile(const std::string& path, std::int64_t max_bytes, std::size_t* size_out) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) throw IoError(path, "no such file");
  if (!std::filesystem::is_regular_file(status)) throw IoError(path, "not a regular file");
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) throw IoError(path, "cannot read file size");
  if (static_cast<std::int64_t>(size) > max_bytes) {
    throw IoError(path, "file of " + std::to_string(size) + " bytes exceeds the input limit of " +
                            std::to_string(max_bytes) + " bytes");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path, "cannot open file");
  *size_out = static_cast<std::size_t>(size);
  return in;
}

std::string ReadWholeFile(const std::string& path, std::int64_t max_bytes) {
  std::size_t size = 0;
  std::ifstream in = OpenWholeFile(path, max_bytes, &size);
  std::string bytes(size, '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(size));
  if (static_cast<std::uint64_t>(in.gcount()) != size) throw IoError(path, "read failed");
  return bytes;
}

std::vector<std::string_view> SplitWhitespace(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r') ++j;
    if (j > i) out.push_back(line.substr(i, j - i));
    i = j;
  }
  return out;
}

bool ParseDouble(std::string_view token, double* value) {
  if (token.empty() || token.size() > 64) return false;
  // strtod accepts what std::from_chars does plus a leading '+'; copy so it is NUL-terminated.
  char buf[65];
  token.copy(buf, token.size());
  buf[token.size()] = '\0';
  char* end = nullptr;
  const double v = std::strtod(buf, &end);
  if (end != buf + token.size() || !std::isfinite(v)) return false;
  *value = v;
  return true;
}

bool ParseInt64(std::string_view token, std::int64_t* value) {
  if (token.empty()) return false;
  std::int64_t v = 0;
  const auto [ptr, ec] = std::from_chars(token.data(), token.data() + token.size(), v);
  if (ec != std::errc() || ptr != token.data() + token.size() || v < 0) return false;
  *value = v;
  return true;
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
    s.remove_suffix(1);
  return s;
}

LineReader::LineReader(const std::string& text, std::string name)
    : text_(text), name_(std::move(name)) {}

bool LineReader::Next(std::string_view* line) {
  if (pos_ >= text_.size()) return false;
  std::size_t end = text_.find('\n', pos_);
  if (end == std::string::npos) end = text_.size();
  std::string_view l(text_.data() + pos_, end - pos_);
  if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
  pos_ = end + 1;
  ++line_number_;
  if (line_number_ > GlobalInputLimits().max_lines) {
    throw IoError(name_, line_number_, "more lines than the input limit allows");
  }
  *line = l;
  return true;
}

}  // namespace planeslam::datasets::detail
