// Fuzzes the YAML configuration loader (all registered sections).
#include <cstdint>
#include <string>

#include "config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  planeslam::app::Config config;
  try {
    config.LoadString(std::string(reinterpret_cast<const char*>(data), size), "fuzz.yaml");
    (void)config.ToYaml(true);
  } catch (const planeslam::ConfigError&) {
  } catch (const planeslam::IoError&) {
  }
  return 0;
}
