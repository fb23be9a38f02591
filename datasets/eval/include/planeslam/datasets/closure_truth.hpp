#pragma once
/// Ground truth of a loop closure: whether its measured relative pose is the true one. Computed
/// by the evaluation from the ground-truth trajectory, never by the SLAM that proposed it.
#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::datasets {

struct ClosureTruthOptions {
  double max_time_difference = 0.01;  ///< [s] a stamp matches a ground-truth pose within this
  double max_translation = 0.05;      ///< [m] a true closure is within this of the truth
  double max_rotation_deg = 2.0;      ///< [deg] and within this
};

struct ClosureTruth {
  bool known = false;    ///< both stamps have a ground-truth pose
  bool correct = false;  ///< the measured relative pose matches the true one within tolerance
  double translation_error = 0.0;   ///< [m] |t| of true^-1 * measured
  double rotation_error_deg = 0.0;  ///< [deg] its rotation angle
};

/// Judges the closure T_from_to measured between the frames at `stamp_from` and `stamp_to`.
ClosureTruth JudgeClosure(const Trajectory& ground_truth, double stamp_from, double stamp_to,
                          const Pose& T_from_to, const ClosureTruthOptions& options = {});

}  // namespace planeslam::datasets
