#pragma once
/// `planeslam bench detect --quality`: detection quality against ground truth for every method.
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "config.hpp"

namespace planeslam::app::bench {

struct QualityOptions {
  int synthetic_frames = 12;   ///< frames per synthetic sequence, evenly spread over it
  int tum_stride = 10;         ///< TUM repeatability: frame i = 0, stride, 2 stride, ...
  std::vector<int> tum_k = {1, 5, 15};  ///< frame gaps of the repeatability pairs
  double tolerance = 0.8;      ///< Hoover's T
  std::int64_t min_gt_pixels = 2000;  ///< "large" ground-truth planes [px]
  std::int64_t repeat_large_pixels = 5000;  ///< repeatability: planes that must find a partner
  std::string data_dir;
  std::string json_path;       ///< empty = none
  std::string plot_dir;        ///< empty = none
  bool quiet = false;
};

/// Runs the synthetic (room, rubble; pinhole and spherical sensors, with noise) segmentation
/// quality and the TUM repeatability for `methods`, prints one table, writes JSON/plots when
/// asked. Returns the exit code.
int RunQualitySuite(const std::vector<Method>& methods, const Config& config,
                    const QualityOptions& options);

/// One detection timing for the time plots.
struct TimingSample {
  std::string method;
  double ms = 0.0;
  int planes = 0;
};

/// Box plot of times per method and scatter of time vs planes (log10 ms), into `dir`.
void WriteTimePlots(const std::string& dir, const std::vector<std::string>& methods,
                    const std::vector<TimingSample>& samples);

}  // namespace planeslam::app::bench
