// Fuzzes the depth.txt / associations.txt frame-list parser.
#include <cstdint>
#include <string>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/tum_sequence.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  for (int columns : {2, 4}) {
    try {
      const auto entries = planeslam::datasets::ParseFrameList(text, "fuzz.txt", columns);
      for (std::size_t i = 1; i < entries.size(); ++i) {
        // The parser promises strictly increasing stamps.
        if (!(entries[i].timestamp > entries[i - 1].timestamp)) __builtin_trap();
      }
    } catch (const planeslam::IoError&) {
    }
  }
  return 0;
}
