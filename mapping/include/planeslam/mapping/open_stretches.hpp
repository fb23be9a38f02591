#pragma once
/// Offline smoothing of the stretches of a trajectory where tracking left directions to the
/// motion prior (a blank wall fills the view: the planes fix the distance to it and its tilt,
/// nothing fixes the motion along it).
///
/// While tracking, such a stretch continues the velocity measured before it (constant velocity),
/// and the pose graph then corrects it as a whole where measurements resume: the poses inside
/// are the extrapolation plus a correction growing linearly along the stretch, off by about
/// a T^2 / 8 for an acceleration a over a stretch of T seconds. Once the run is over the motion
/// on both sides is known, and the positions in the stretch are re-interpolated along its open
/// translations only by the cubic Hermite curve through the measured positions and velocities at
/// its two ends (the posterior mean of a white-noise-acceleration motion between two known
/// states), which is off by the change of acceleration alone. The measured directions and the
/// rotations are kept: over a turn of a second or more, a curve through rotation vectors strays
/// further than the held turn the tracking continued.
#include <Eigen/Core>
#include <vector>

#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::mapping {

/// A pose of a tracked trajectory and what its tracking left to the motion prior.
struct TrackedPose {
  double timestamp = 0.0;  ///< [s]
  Pose T_world = Pose::Identity();
  /// Unit directions (world axes; translation, then rotation, each column one or the other) its
  /// tracking left to the prior; none when it measured all six. Only the translations move.
  Eigen::Matrix<double, 6, Eigen::Dynamic> open = Eigen::Matrix<double, 6, 0>();
  /// A keyframe's pose (the pose graph's): judged as an outlier after the other poses.
  bool keyframe = false;
};

/// Replaces the position of every pose that the motion on both sides contradicts by that motion's
/// prediction, and returns their indices (sorted): a registration that matched a wrongly fitted
/// sliver of a plane, or a fill that slid along a wall, for a frame or two. Keyframes are judged
/// once the other poses' outliers are replaced: the graph holds a keyframe whose own registration
/// slid where nothing else ties it down, while the frames tracked after it are corrected towards
/// the next keyframe (the map keeps what that keyframe's pose placed). The prediction is the
/// Hermite curve between the states read from the five poses on each side (Theil-Sen lines,
/// robust to a second wrong pose among them), exact on any motion of constant acceleration. A
/// pose is an outlier when it is off its prediction by more than ten times the median of that
/// distance over the poses within fifty frames, and by more than a millimetre; the worst is
/// replaced first and its neighbours judged again. The five poses at either end are not judged;
/// rotations are kept. Timestamps must increase.
std::vector<std::size_t> ReinterpolateOutliers(std::vector<TrackedPose>* poses);

/// Re-interpolates the open translations of every stretch of consecutive poses with open
/// directions that has measured poses on both sides (a stretch at the start or the end of the
/// trajectory is left as it is); a run of fewer than three measured poses inside a stretch is
/// part of it (its poses stay). Each end is the Theil-Sen line through the measured poses
/// within `velocity_span` [s] on its side (at least three, else the stretch is left as it is),
/// taken at its middle, so one frame's error does not bend the curve. Timestamps must increase.
void SmoothOpenStretches(std::vector<TrackedPose>* poses, double velocity_span);

}  // namespace planeslam::mapping
