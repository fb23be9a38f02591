#pragma once
// Private helpers shared by the range-data readers: whole-file reads with size limits, strict
// number parsing and line splitting. Not part of the public API.
#include <cstdint>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

namespace planeslam::datasets::detail {

/// Reads a whole file. Throws IoError naming `path` when it is missing, not a regular file, or
/// larger than `max_bytes`.
std::string ReadWholeFile(const std::string& path, std::int64_t max_bytes);
/// ReadWholeFile's checks (exists, regular, at most max_bytes, opens); returns the open stream
/// and the file's size, for readers that read straight into their own buffer.
std::ifstream OpenWholeFile(const std::string& path, std::int64_t max_bytes, std::size_t* size);

/// Largest file any reader accepts: the biggest image/cloud the limits allow, generously sized
/// (a float32 x y z + 5 extra fields per pixel), so the limits stay the one knob.
std::int64_t MaxInputFileBytes();

/// Splits on spaces and tabs (no empty tokens).
std::vector<std::string_view> SplitWhitespace(std::string_view line);

/// Strict parse of a whole token as a finite double; false on text, trailing junk, NaN or inf.
bool ParseDouble(std::string_view token, double* value);
/// Strict parse of a whole token as a non-negative integer (decimal digits only).
bool ParseInt64(std::string_view token, std::int64_t* value);

/// Strips a trailing '\r' (files written on Windows) and surrounding blanks.
std::string_view Trim(std::string_view s);

/// Iterates lines of a text buffer; counts lines and refuses more than the configured limit.
class LineReader {
 public:
  LineReader(const std::string& text, std::string name);
  /// Next line without its newline (and '\r'); false at the end.
  bool Next(std::string_view* line);
  long line_number() const { return line_number_; }

 private:
  const std::string& text_;
  std::string name_;
  std::size_t pos_ = 0;
  long line_number_ = 0;
};

}  // namespace planeslam::datasets::detail
