#pragma once
/// `planeslam bench io`: the input readers on the shared data, in one process. Per file: reading
/// the bytes, and decoding them: PNG depth with libpng alone (the reference) and with DecodePng16
/// (libdeflate, the reader planeslam uses), KITTI .bin and PCD with their readers. Reports ms a
/// file (median over the repetitions, summed over the files) and the PNG ratio, and checks that
/// both PNG decoders give the same pixels.
#include <string>
#include <vector>

namespace planeslam::app::bench {

struct IoBenchOptions {
  std::string data_dir;  ///< the shared data folder
  int repeat = 5;        ///< decodes per file (the median counts)
  std::string json_path;  ///< empty = none
};

/// Runs the benchmark, prints a table; returns the exit code (non-zero when a decoder disagrees).
int RunIoBench(const IoBenchOptions& options);

}  // namespace planeslam::app::bench
