// Fuzzes the 16-bit PNG decoder (depth images, label images), differentially: DecodePng16 and
// libpng alone must agree on every input (same pixels, or the same error message).
#include <cstdint>
#include <string>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/image_io.hpp"

namespace {

std::string Decode(planeslam::datasets::Image16 (*decode)(const std::string&, const std::string&),
                   const std::string& bytes, planeslam::datasets::Image16* image) {
  try {
    *image = decode(bytes, "fuzz.png");
    if (image->data.size() != static_cast<std::size_t>(image->width) * image->height) {
      __builtin_trap();
    }
  } catch (const planeslam::IoError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  planeslam::datasets::Image16 fast, reference;
  const std::string fast_error = Decode(&planeslam::datasets::DecodePng16, bytes, &fast);
  const std::string reference_error =
      Decode(&planeslam::datasets::DecodePng16WithLibpng, bytes, &reference);
  if (fast_error != reference_error || fast.width != reference.width ||
      fast.data != reference.data) {
    __builtin_trap();
  }
  return 0;
}
