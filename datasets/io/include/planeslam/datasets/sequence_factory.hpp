#pragma once
/// Opens whatever range data a path holds: a sequence folder (TUM, ICL-NUIM, PCD, KITTI .bin) or a
/// single frame for `planeslam detect`.
#include <memory>
#include <string>

#include "planeslam/datasets/sensor_config.hpp"
#include "planeslam/datasets/sequence.hpp"

namespace planeslam::datasets {

/// Folder layouts OpenSequence recognises.
enum class SequenceLayout {
  kTum,        ///< depth.txt + depth/*.png (+ groundtruth.txt, intrinsics.yaml)
  kIclNuim,    ///< associations.txt + depth/N.png (+ groundtruth.txt indexed by N)
  kPcdFolder,  ///< *.pcd organized clouds, sorted by file name
  kKittiBin,   ///< *.bin Velodyne scans (float32 x y z reflectance), sorted by file name
};

/// "tum", "icl", "pcd" or "kitti".
std::string ToString(SequenceLayout layout);

/// Decides the layout of `folder`: depth.txt -> TUM; associations.txt -> ICL-NUIM; any *.pcd ->
/// PCD folder; any *.bin -> KITTI. Throws IoError for a missing path, a file, or a folder holding
/// none of these (an empty folder says so).
SequenceLayout DetectLayout(const std::string& folder);

/// Opens the sequence in `folder` with the detected layout. Throws IoError naming the file (and
/// line) on bad data, ConfigError on an invalid config.
std::unique_ptr<Sequence> OpenSequence(const std::string& folder, const SensorConfig& config);

/// Reads one frame for `detect`: a 16-bit depth PNG (back-projected with config.intrinsics,
/// depth_scale and flip_y), an organized .pcd (scaled by unit_scale), or a KITTI .bin (projected
/// to a range image). Decided by the extension. Frame index 0, timestamp 0, no ground truth.
Frame LoadSingleFrame(const std::string& path, const SensorConfig& config);

}  // namespace planeslam::datasets
