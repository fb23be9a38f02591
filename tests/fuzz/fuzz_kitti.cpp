// Fuzzes the KITTI .bin parser and the range-image projection.
#include <cstdint>
#include <string>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/kitti_scan.hpp"
#include "planeslam/datasets/sensor_config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const auto scan = planeslam::datasets::ParseKittiScan(
        std::string(reinterpret_cast<const char*>(data), size), "fuzz.bin");
    const planeslam::datasets::SensorConfig config;
    const auto cloud = planeslam::datasets::ProjectToRangeImage(scan, config);
    if (cloud.points.size() != static_cast<std::size_t>(cloud.width) * cloud.height) {
      __builtin_trap();
    }
  } catch (const planeslam::IoError&) {
  }
  return 0;
}
