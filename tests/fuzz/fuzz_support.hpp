#pragma once
// Helpers for the libFuzzer targets: expected input errors (IoError, ConfigError) are fine, any
// other exception, crash or sanitizer report is a finding.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

namespace planeslam::fuzz {

/// Writes the input to a per-process temporary file (for parsers that take a path).
inline std::string WriteTemp(const std::uint8_t* data, std::size_t size, const char* suffix) {
  const std::string path =
      "/tmp/planeslam_fuzz_" + std::to_string(::getpid()) + suffix;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f) {
    if (size) std::fwrite(data, 1, size, f);
    std::fclose(f);
  }
  return path;
}

}  // namespace planeslam::fuzz
