#pragma once
/// Limits every reader checks before allocating, so a header that claims 10^12 points or a
/// 10^6 x 10^6 image is refused with a clear error instead of exhausting memory.
#include <cstdint>

namespace planeslam::datasets {

struct InputLimits {
  std::int64_t max_pixels = 64LL * 1024 * 1024;   ///< per image / organized cloud (64 Mpx)
  std::int64_t max_points = 64LL * 1024 * 1024;   ///< per unorganized scan (e.g. KITTI .bin)
  std::int64_t max_side = 65535;                  ///< image width or height [px]
  std::int64_t max_lines = 50LL * 1000 * 1000;    ///< lines in a text file (trajectories, lists)
};

/// Process-wide limits (set once from the config's `limits` section before reading).
InputLimits& GlobalInputLimits();

}  // namespace planeslam::datasets
