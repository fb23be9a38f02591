#pragma once
/// The KITTI odometry benchmark's segment errors, with the semantics of its devkit
/// (devkit_odometry, evaluate_odometry.cpp: trajectoryDistances, lastFrameFromSegmentLength,
/// calcSequenceErrors):
///  - dist[i]: path length of the ground truth up to frame i (sum of the steps between
///    consecutive positions);
///  - segments start at every `step`-th frame f (0, 10, 20, ...); for each length L (100, 200,
///    ..., 800 m) the segment ends at the first frame l with dist[l] > dist[f] + L, and is skipped
///    when there is none;
///  - error pose E = inv(inv(P_f) P_l) (inv(Q_f) Q_l) (P estimate, Q ground truth);
///    t_err = |translation of E| / L, r_err = rotation angle of E / L (the angle from the trace,
///    acos(clamp((tr - 1) / 2)));
///  - the sequence's figures are the means of t_err and r_err over all segments, printed as %
///    (t_err x 100) and deg/100 m (r_err x 180/pi x 100); the per-length figures average the
///    segments of one length.
/// The devkit computes in single precision; this computes in double, which changes the figures
/// by less than 1e-5 of their value. Pure computation.
#include <cstddef>
#include <string>
#include <vector>

#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::datasets {

struct KittiOdometryOptions {
  std::vector<double> lengths = {100, 200, 300, 400, 500, 600, 700, 800};  ///< [m]
  std::size_t step = 10;  ///< first frames every `step` frames (the devkit's step_size)
};

/// One segment.
struct KittiSegmentError {
  std::size_t first_frame = 0;
  std::size_t last_frame = 0;
  double length = 0.0;  ///< nominal length L [m]
  double t_err = 0.0;   ///< |t(E)| / L [1]
  double r_err = 0.0;   ///< angle(E) / L [rad/m]
};

/// Means over the segments of one length.
struct KittiLengthErrors {
  double length = 0.0;  ///< [m]
  std::size_t segments = 0;
  double t_err = 0.0;  ///< [1]
  double r_err = 0.0;  ///< [rad/m]
};

struct KittiOdometryResult {
  bool ok = false;      ///< false: no segment (ground truth shorter than the shortest length)
  std::string message;  ///< why not ok
  std::vector<KittiSegmentError> segments;
  std::vector<KittiLengthErrors> per_length;  ///< lengths with at least one segment
  double t_err = 0.0;                         ///< mean over all segments [1]
  double r_err = 0.0;                         ///< mean over all segments [rad/m]
  double path_length = 0.0;                   ///< ground truth's path length [m]

  double TranslationPercent() const { return 100.0 * t_err; }
  double RotationDegPer100m() const;
};

/// dist[i]: path length of `poses` up to pose i (dist[0] = 0) [m].
std::vector<double> KittiTrajectoryDistances(const std::vector<Pose>& poses);

/// First frame l >= first with dist[l] > dist[first] + length; -1 when there is none.
long KittiLastFrameFromSegmentLength(const std::vector<double>& dist, std::size_t first,
                                     double length);

/// Segment errors of `est` against `gt`, paired by index (same length, checked).
KittiOdometryResult EvaluateKittiOdometry(const std::vector<Pose>& gt,
                                          const std::vector<Pose>& est,
                                          const KittiOdometryOptions& options = {});

}  // namespace planeslam::datasets
