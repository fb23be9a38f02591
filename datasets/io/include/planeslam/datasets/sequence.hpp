#pragma once
/// A sequence of range frames with optional ground truth, whatever the source format.
#include <cstddef>
#include <memory>
#include <optional>
#include <string>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::datasets {

/// One range frame.
struct Frame {
  std::size_t index = 0;                ///< position in the sequence
  double timestamp = 0.0;               ///< [s]
  std::string source;                   ///< file it was read from (for messages)
  OrganizedCloud cloud;                 ///< metres, sensor frame
  int decimation = 1;  ///< cloud holds every n-th row and column of the sensor's grid (Decimate)
  std::optional<Pose> T_world_sensor_gt;  ///< ground-truth pose when the sequence has one
};

/// Random-access source of frames. Load() reads from disk (or generates) on demand and throws
/// IoError naming the file on bad data.
class Sequence {
 public:
  virtual ~Sequence() = default;
  virtual std::size_t Size() const = 0;
  virtual Frame Load(std::size_t index) const = 0;
  /// Load at 1/factor resolution: the same points as Decimate(Load(index).cloud, factor), with
  /// frame.decimation = factor. Readers that can skip the other pixels override it.
  virtual Frame LoadDecimated(std::size_t index, int factor) const {
    Frame frame = Load(index);
    if (factor > 1) {
      frame.cloud = Decimate(frame.cloud, factor);
      frame.decimation = factor;
    }
    return frame;
  }
  /// Human-readable name (folder or scene).
  virtual std::string Name() const = 0;
  /// Timestamp of frame i without loading it.
  virtual double Timestamp(std::size_t index) const = 0;
  /// Ground-truth pose of frame i, if known, without loading it.
  virtual std::optional<Pose> GroundTruth(std::size_t index) const = 0;
};

}  // namespace planeslam::datasets
