// Fuzzes the 16-bit PNG decoder (depth images, label images).
#include <cstdint>
#include <string>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/image_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const auto image = planeslam::datasets::DecodePng16(
        std::string(reinterpret_cast<const char*>(data), size), "fuzz.png");
    if (image.data.size() != static_cast<std::size_t>(image.width) * image.height) __builtin_trap();
  } catch (const planeslam::IoError&) {
  }
  return 0;
}
