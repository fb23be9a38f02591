#pragma once
/// Depth-image sequences: the TUM RGB-D layout (depth.txt + depth/*.png + groundtruth.txt) and the
/// ICL-NUIM TUM-compatible layout (associations.txt + depth/N.png + groundtruth.txt indexed by N).
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "planeslam/datasets/depth_image.hpp"
#include "planeslam/datasets/sensor_config.hpp"
#include "planeslam/datasets/sequence.hpp"
#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::datasets {

/// One line of a frame list: stamp [s] and the file relative to the list's folder.
struct FrameListEntry {
  double timestamp = 0.0;
  std::string file;
  long line = 0;  ///< line in the list file (for messages)
};

/// Parses a TUM-style frame list (`stamp file` per line, `#` comments). `columns`: how many
/// whitespace-separated columns a line must have (depth.txt: 2; ICL associations.txt: 4, of which
/// the first two are used). Throws IoError(name, line, reason) on a wrong column count, a bad
/// number, or a stamp not strictly after the previous one (unsorted or duplicate).
std::vector<FrameListEntry> ParseFrameList(const std::string& text, const std::string& name,
                                           int columns);

/// For each frame stamp, the ground-truth pose with the nearest stamp when it is within
/// `max_difference` seconds (TUM's associate.py default 0.02 s), else nullopt.
/// `gt.stamps` must be sorted (trajectory readers guarantee it).
std::vector<std::optional<Pose>> AssociateByTime(const std::vector<double>& frame_stamps,
                                                 const Trajectory& gt, double max_difference);

/// A sequence of 16-bit depth PNGs with stamps and optional ground truth.
class DepthImageSequence : public Sequence {
 public:
  struct Item {
    double timestamp = 0.0;
    std::string path;  ///< absolute or relative to the working directory
    std::optional<Pose> T_world_sensor_gt;
    std::string list;        ///< the frame list that names the file (for messages)
    long list_line = 0;      ///< its line there
    std::string list_entry;  ///< the file as the list spells it
  };

  DepthImageSequence(std::string name, std::vector<Item> items, const PinholeIntrinsics& intrinsics,
                     double depth_scale, double min_depth, double max_depth);

  std::size_t Size() const override { return items_.size(); }
  Frame Load(std::size_t index) const override;
  /// Back-projects only the pixels kept (the PNG is still decoded whole: its rows depend on
  /// each other).
  Frame LoadDecimated(std::size_t index, int factor) const override;
  std::string Name() const override { return name_; }
  double Timestamp(std::size_t index) const override;
  std::optional<Pose> GroundTruth(std::size_t index) const override;

  /// Intrinsics actually used (fy < 0 for a flipped y axis).
  const PinholeIntrinsics& intrinsics() const { return projector_.intrinsics(); }
  double depth_scale() const { return depth_scale_; }
  /// Frames with an associated ground-truth pose.
  std::size_t GroundTruthCount() const;
  /// Frame `index`'s list entry: stamp, depth file, ground-truth pose.
  const Item& item(std::size_t index) const { return items_.at(index); }

 private:
  std::string name_;
  std::vector<Item> items_;
  DepthProjector projector_;
  double depth_scale_;
};

/// Opens a TUM RGB-D folder: depth.txt (a listed file that is missing makes Load of that frame
/// throw IoError(depth.txt, line, ...), a bad frame like an unreadable PNG), intrinsics
/// from the folder's intrinsics.yaml when present and config.intrinsics_source is "auto" (else
/// config.intrinsics, depth_scale, flip_y), groundtruth.txt (optional) associated by nearest stamp
/// within config.gt_max_time_difference. Throws IoError naming the file (and line).
std::unique_ptr<DepthImageSequence> OpenTumSequence(const std::string& folder,
                                                    const SensorConfig& config);

/// Opens an ICL-NUIM TUM-compatible folder: associations.txt (`N depth/N.png N rgb/N.png`),
/// depth PNG / 5000 = metres, groundtruth.txt `N tx ty tz qx qy qz qw` matched by frame number N.
/// With intrinsics_source "auto" the folder's intrinsics.yaml is used, else ICL-NUIM's published
/// camera with fy = -480: the clouds then agree with ICL's ground truth as published (its camera
/// frame has y up). With "config", config.intrinsics/depth_scale/flip_y are used as given.
std::unique_ptr<DepthImageSequence> OpenIclSequence(const std::string& folder,
                                                    const SensorConfig& config);

}  // namespace planeslam::datasets
