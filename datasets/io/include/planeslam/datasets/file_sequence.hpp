#pragma once
/// Sequences of one file per frame (organized PCD folders, KITTI .bin folders): files sorted by
/// name, timestamps from the names when they hold increasing numbers, else the frame index.
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "planeslam/datasets/sensor_config.hpp"
#include "planeslam/datasets/sequence.hpp"

namespace planeslam::datasets {

/// Regular files in `folder` whose extension is `extension` (case-insensitive, with the dot), in
/// natural order: digit runs compare by value, so "scan2" precedes "scan10".
std::vector<std::string> ListFrameFiles(const std::string& folder, const std::string& extension);

/// A timestamp [s] from a file name: "YYYYMMDDTHHMMSS[.ffffff]" (as PCL's grabber names frames)
/// gives seconds since 1970 UTC; otherwise the last number in the stem ("1341836537.655691.pcd",
/// "scan007.pcd" -> 7). nullopt when the name holds no number.
std::optional<double> TimestampFromFileName(const std::string& path);

/// Marks points outside [min_range, max_range] (max 0 = no limit) invalid: depth z for pinhole
/// clouds, Euclidean range for spherical ones.
void ApplyRangeLimits(OrganizedCloud* cloud, double min_range, double max_range);

/// One file per frame, read by `loader` on demand.
class FileSequence : public Sequence {
 public:
  using Loader = std::function<OrganizedCloud(const std::string& path)>;

  /// Timestamps come from the file names when every name has a number and they increase
  /// strictly, else they are the indices; `stamps`, when not empty (one per file), overrides.
  /// `gt` is empty or one entry per file.
  FileSequence(std::string name, std::vector<std::string> files, Loader loader,
               std::vector<std::optional<Pose>> gt = {}, std::vector<double> stamps = {});

  std::size_t Size() const override { return files_.size(); }
  Frame Load(std::size_t index) const override;
  std::string Name() const override { return name_; }
  double Timestamp(std::size_t index) const override;
  std::optional<Pose> GroundTruth(std::size_t index) const override;
  const std::vector<std::string>& files() const { return files_; }

 private:
  std::string name_;
  std::vector<std::string> files_;
  std::vector<double> stamps_;
  Loader loader_;
  std::vector<std::optional<Pose>> gt_;
};

/// A folder of organized PCD files (coordinates times config.unit_scale, grid model
/// config.pcd_model). A `groundtruth.txt` beside them (TUM format) gives each file the pose with
/// the nearest stamp within config.gt_max_time_difference. Throws IoError for a missing folder,
/// one without .pcd files, or a bad groundtruth.txt. A cloud with HEIGHT 1 (unorganized) is
/// refused when loaded.
std::unique_ptr<FileSequence> OpenPcdFolder(const std::string& folder, const SensorConfig& config);

/// Reads one organized PCD with the config's unit scale, model and range limits; refuses an
/// unorganized (HEIGHT 1) cloud with an IoError.
OrganizedCloud ReadOrganizedPcd(const std::string& path, const SensorConfig& config);

}  // namespace planeslam::datasets
