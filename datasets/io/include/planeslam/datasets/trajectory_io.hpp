#pragma once
/// Reading and writing trajectories: TUM, KITTI and EuRoC ground-truth CSV.
///
/// Readers are strict where the popular tools trip users up (evo's "8 entries per row", unsorted or
/// duplicate stamps, non-unit quaternions): every problem is an IoError naming the file and line.
/// Writers go through AtomicOutputFile and print every number in its shortest round-trip form, so a
/// written trajectory reads back bit for bit.
#include <string>
#include <vector>

#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::datasets {

/// The trajectory file formats we read and write.
enum class TrajectoryFormat {
  kTum,    ///< `t tx ty tz qx qy qz qw`, whitespace separated, `#` comments, t in seconds
  kKitti,  ///< 12 numbers a line: the 3x4 matrix [R|t] row-major; no stamps (optional times file)
  kEuroc,  ///< CSV `t[ns], px, py, pz, qw, qx, qy, qz[, ...]` (EuRoC state_groundtruth_estimate0)
};

/// "tum", "kitti" or "euroc".
std::string ToString(TrajectoryFormat format);

/// Parses "tum", "kitti" or "euroc"; throws ConfigError otherwise.
TrajectoryFormat ParseTrajectoryFormat(const std::string& name);

/// Looks at the first data line of `path`: a comma means EuRoC, 8 columns TUM, 12 columns KITTI.
/// Throws IoError (file, line, reason) when the file cannot be read or matches no format.
TrajectoryFormat DetectTrajectoryFormat(const std::string& path);

/// Tolerances of the readers on rotations. Files print quaternions with 4 to 9 decimals, so a unit
/// quaternion is "unit" only up to rounding.
struct TrajectoryReadOptions {
  /// |‖q‖ - 1| (or ‖RᵀR - I‖ for KITTI) up to this: rounding in the file, normalised silently.
  double silent_tolerance = 1e-3;  ///< [-]
  /// Up to this: normalised with a warning; beyond: refused with an IoError naming the line.
  double max_tolerance = 0.05;  ///< [-]
  /// What to do with a line whose stamp equals the previous one. Real files have them (the TUM
  /// fr2/desk ground truth repeats 1311868229.5760): the TUM tools keep the last (a Python dict),
  /// evo's nearest-stamp search uses the first.
  enum class Duplicates { kError, kKeepFirst, kKeepLast };
  Duplicates duplicates = Duplicates::kError;
  /// Appended to the duplicate-stamp error (an app names its option for choosing a policy).
  std::string duplicate_hint;
};

/// Non-fatal findings of a reader (normalised rotations), for the app to print.
struct TrajectoryReadReport {
  std::vector<std::string> warnings;
};

/// Reads a TUM file. Throws IoError(file, line, reason) on a wrong column count, text in a number,
/// NaN/inf, a stamp before the previous one (unsorted), a repeated stamp (unless
/// options.duplicates says which to keep; the report then names the lines), a quaternion far from
/// unit length, or a file with no poses.
Trajectory ReadTumTrajectory(const std::string& path, TrajectoryReadReport* report = nullptr,
                             const TrajectoryReadOptions& options = {});

/// Reads a KITTI pose file. Stamps come from `times_path` (one number a line, as KITTI's
/// times.txt) when given, else they are the frame indices 0, 1, 2, ...
Trajectory ReadKittiTrajectory(const std::string& path, const std::string& times_path = "",
                               TrajectoryReadReport* report = nullptr,
                               const TrajectoryReadOptions& options = {});

/// Reads an EuRoC ground-truth CSV (stamps in nanoseconds, quaternion w first); extra columns
/// (velocities, biases) are ignored. Stamps are returned in seconds.
Trajectory ReadEurocTrajectory(const std::string& path, TrajectoryReadReport* report = nullptr,
                               const TrajectoryReadOptions& options = {});

/// Dispatches on `format`; `kitti_times_path` is used only for KITTI.
Trajectory ReadTrajectory(const std::string& path, TrajectoryFormat format,
                          TrajectoryReadReport* report = nullptr,
                          const std::string& kitti_times_path = "",
                          const TrajectoryReadOptions& options = {});

/// Writes `t tx ty tz qx qy qz qw` lines (qw >= 0), atomically, shortest round-trip numbers.
void WriteTumTrajectory(const std::string& path, const Trajectory& trajectory);

/// Writes 12 numbers a line (row-major [R|t]), atomically; when `times_path` is not empty the
/// stamps go there, one a line (KITTI's times.txt).
void WriteKittiTrajectory(const std::string& path, const Trajectory& trajectory,
                          const std::string& times_path = "");

/// The shortest decimal text that reads back as exactly `value` (std::to_chars).
std::string FormatRoundTrip(double value);

}  // namespace planeslam::datasets
