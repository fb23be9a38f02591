// Fuzzes the PCD parser (ascii, binary, binary_compressed; lying headers).
#include <cstdint>
#include <string>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/pcd_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const auto cloud = planeslam::datasets::ParsePcd(
        std::string(reinterpret_cast<const char*>(data), size), "fuzz.pcd");
    if (cloud.points.size() != static_cast<std::size_t>(cloud.width) * cloud.height) {
      __builtin_trap();
    }
  } catch (const planeslam::IoError&) {
  }
  return 0;
}
