#pragma once
/// Error types shared by every planeslam module.
///
/// Tiers: a broken precondition in code is a PLANESLAM_CHECK failure;
/// expected data conditions (no planes, degenerate geometry) are flags in result structs; IO and
/// config failures are IoError / ConfigError carrying the file (and line or key) and the reason.
/// main() turns an exception into one line on stderr and a non-zero exit code.
#include <sstream>
#include <stdexcept>
#include <string>

namespace planeslam {

/// A file could not be read or written, or its content is invalid. what() is "FILE: reason" or
/// "FILE:LINE: reason".
class IoError : public std::runtime_error {
 public:
  IoError(const std::string& file, const std::string& reason)
      : std::runtime_error(file + ": " + reason), file_(file) {}
  IoError(const std::string& file, long line, const std::string& reason)
      : std::runtime_error(file + ":" + std::to_string(line) + ": " + reason), file_(file) {}
  const std::string& file() const { return file_; }

 private:
  std::string file_;
};

/// A configuration value is unknown, mistyped or out of range. what() names file, key and reason.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A broken precondition inside planeslam (a bug, not bad input).
class CheckError : public std::logic_error {
 public:
  using std::logic_error::logic_error;
};

}  // namespace planeslam

/// Precondition check that stays on in Release builds; throws planeslam::CheckError.
#define PLANESLAM_CHECK(cond, msg)                                                    \
  do {                                                                                \
    if (!(cond)) {                                                                    \
      std::ostringstream planeslam_check_os_;                                         \
      planeslam_check_os_ << __FILE__ << ":" << __LINE__ << ": check failed: " #cond  \
                          << ": " << msg;                                             \
      throw ::planeslam::CheckError(planeslam_check_os_.str());                       \
    }                                                                                 \
  } while (0)
