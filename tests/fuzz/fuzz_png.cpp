// Fuzzes the 16-bit PNG reader (depth images, label images).
#include <cstdint>

#include "fuzz_support.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/image_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = planeslam::fuzz::WriteTemp(data, size, ".png");
  try {
    const auto image = planeslam::datasets::ReadPng16(path);
    if (image.data.size() != static_cast<std::size_t>(image.width) * image.height) __builtin_trap();
  } catch (const planeslam::IoError&) {
  }
  return 0;
}
