// Fuzzes the g2o pose-graph parser.
#include <cstdint>
#include <sstream>
#include <string>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/mapping/g2o_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  try {
    const auto graph = planeslam::mapping::ParseG2o(in, "fuzz.g2o");
    (void)planeslam::mapping::FormatG2o(graph);
  } catch (const planeslam::IoError&) {
  }
  return 0;
}
